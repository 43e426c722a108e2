"""Moves are never doubled: a move that times out is stopped (the driver's ``stop()``), and a retry waits until
that move has really ended before it sends the next one. Pinned with a simulated arm that hangs."""

from __future__ import annotations

import threading
import time
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import pytest

from devices.sim import SimulatedArm
from planner import Pose
from tests.helpers import SMALL, wait_until
from workbench.errors import DeviceFault
from workbench.registry.registry import SessionRegistry
from workbench.session.session import Session
from workbench.settings import WorkbenchSettings


class HangingArm(SimulatedArm):
    """A simulated arm whose next move hangs until ``stop()``; it then needs ``brake`` seconds to halt (like a
    real arm decelerating). ``overlap`` records the most moves that were ever in progress at once."""

    def __init__(self, pose: Pose, brake: float) -> None:
        super().__init__(pose)
        self.hang_next = True
        self.brake = brake
        self.active = 0
        self.overlap = 0
        self.ended_at: list[float] = []
        self.started_at: list[float] = []
        self._stopped = threading.Event()
        self._lock = threading.Lock()

    def move_to(self, T_base_camera: Pose) -> None:
        with self._lock:
            self.active += 1
            self.overlap = max(self.overlap, self.active)
            self.started_at.append(time.monotonic())
            hang, self.hang_next = self.hang_next, False
        try:
            if hang:
                self._stopped.wait(30)
                time.sleep(self.brake)
                return  # stopped short: the pose is not the target
            super().move_to(T_base_camera)
        finally:
            with self._lock:
                self.active -= 1
                self.ended_at.append(time.monotonic())

    def stop(self) -> None:
        super().stop()
        self._stopped.set()


@pytest.fixture
def registry(tmp_path: Path) -> Iterator[SessionRegistry]:
    from devices.config import CellConfig, DeviceConfig

    # the hanging arm replaces a pose-driven arm: the reach-sphere cell's
    devices = DeviceConfig(cell=CellConfig(kinematics="reach_sphere"))
    settings = WorkbenchSettings(
        models_dir=tmp_path / "models", data_dir=tmp_path / "data", move_timeout=0.5, devices=devices
    )
    registry = SessionRegistry(settings)
    yield registry
    registry.close()


def hang_on_approve(registry: SessionRegistry, brake: float) -> tuple[Session, HangingArm]:
    session = registry.create(config=SMALL)
    session.capture()
    entry = session.plan()
    faulty: Any = session.cell.arm  # the fault-injection wrapper: stop() reaches the inner arm through it
    arm = HangingArm(faulty.inner.pose, brake=brake)
    faulty.inner = arm
    with pytest.raises(DeviceFault, match=r"cell move: no answer within 0\.5 s \(timeout; stopped\)"):
        session.approve(entry.plan_id, entry.plan.best_index)
    assert arm.stops == 1 and session.status()["state"] == "error" and session.status()["retry"] == "approve"
    return session, arm


def test_a_timed_out_move_is_stopped_and_retry_waits_for_it(registry: SessionRegistry) -> None:
    session, arm = hang_on_approve(registry, brake=0.3)
    record = session.retry()  # the stopped move is still braking: retry waits for it, then moves once
    assert record["iteration"] == 2 and arm.overlap == 1, "two moves were in progress at once"
    assert len(arm.started_at) == 2 and arm.started_at[1] >= arm.ended_at[0]
    assert arm.moves == 1 and session.moves == 2  # the first view, then the retried one (not the stopped move)


def test_a_move_that_does_not_stop_blocks_the_next_one(registry: SessionRegistry) -> None:
    session, arm = hang_on_approve(registry, brake=1.5)
    with pytest.raises(DeviceFault, match="the previous move has not ended"):
        session.retry()
    assert len(arm.started_at) == 1 and session.status()["state"] == "error"  # no second move was sent
    wait_until(lambda: arm.ended_at, 10.0, "the braking move ended")
    assert session.retry()["iteration"] == 2 and arm.overlap == 1 and len(arm.started_at) == 2
