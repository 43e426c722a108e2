"""Fault injection into the devices, the device deadline, and frames on disk."""

from __future__ import annotations

import math
import threading
import time
from pathlib import Path

import numpy as np
import pytest

from devices.builtins import make_builtin
from devices.config import CellConfig
from devices.faults import FaultConfig, FaultInjector, ScheduledFault, interpolate, with_faults
from devices.frames import load_frame, save_frame
from devices.protocols import CaptureError, DeviceError
from devices.sim import make_sim_cell
from devices.timeout import DeviceTimeoutError, call_with_timeout
from planner import DepthFrame, Intrinsics, Pose


@pytest.fixture(scope="module")
def mesh():
    return make_builtin("l-block", 0.2)


def faulty_cell(mesh, **config):
    """A reach-sphere cell (a pose arm) with faults; the joint arm's faults are in test_arm_cell.py."""
    injector = FaultInjector(FaultConfig.from_dict(config))
    return with_faults(make_sim_cell(mesh, cell_config=CellConfig(kinematics="reach_sphere")), injector), injector


def test_config_from_dict_and_its_errors() -> None:
    c = FaultConfig.from_dict({"capture_failure": 0.25, "schedule": [{"kind": "arm_halfway", "at": 2}], "seed": 4})
    assert c.capture_failure == 0.25 and c.schedule == (ScheduledFault("arm_halfway", 2),) and c.enabled
    assert FaultConfig.from_dict(c.to_dict()) == c
    assert not FaultConfig().enabled
    for bad, message in [
        ({"capture_failure": 1.5}, "faults.capture_failure"),
        ({"schedule": [{"kind": "gremlins", "at": 1}]}, "faults.schedule.kind"),
        ({"schedule": [{"kind": "nan_frame", "at": 0}]}, "faults.schedule.at"),
        ({"schedule": [{"kind": "nan_frame"}]}, "faults.schedule"),
        ({"bogus": 1}, "unknown setting"),
        ({"hang_seconds": -1}, "faults.hang_seconds"),
        ([], "expected a table"),
    ]:
        with pytest.raises(ValueError, match=message):
            FaultConfig.from_dict(bad)  # type: ignore[arg-type]


def test_schedule_counts_actions_per_device(mesh) -> None:
    cell, injector = faulty_cell(mesh, schedule=[{"kind": "capture_failure", "at": 3}])
    cell.capture()
    cell.capture()
    with pytest.raises(CaptureError, match="capture failed"):
        cell.capture()
    cell.capture()  # only the 3rd
    assert injector.counts["camera"] == 4
    assert injector.fired == [{"device": "camera", "action": 3, "kind": "capture_failure"}]


def test_probabilities_are_seeded_and_per_device(mesh) -> None:
    def pattern(seed: int) -> list[bool]:
        injector = FaultInjector(FaultConfig(turntable_error=0.5, seed=seed))
        return [injector.draw("turntable") is not None for _ in range(40)]

    assert pattern(1) == pattern(1) and pattern(1) != pattern(2)
    assert 5 < sum(pattern(1)) < 35
    injector = FaultInjector(FaultConfig(turntable_error=1.0))
    assert injector.draw("camera") is None and injector.draw("arm") is None  # not their fault
    assert injector.draw("turntable") == "turntable_error"


def test_injected_fault_comes_first(mesh) -> None:
    injector = FaultInjector(FaultConfig())
    injector.inject("empty_frame")
    assert injector.draw("arm") is None
    assert injector.draw("camera") == "empty_frame" and injector.draw("camera") is None
    with pytest.raises(ValueError, match="fault kind"):
        injector.inject("meteor")


def test_arm_stops_halfway_after_the_turntable_turned(mesh) -> None:
    cell, _ = faulty_cell(mesh, schedule=[{"kind": "arm_halfway", "at": 1}])
    start_arm, start_angle = cell.arm.pose, cell.angle
    target = Pose.look_at([0.3, 0.25, 0.3], [0, 0, 0.08])
    motion = cell.plan_motion(target)
    with pytest.raises(DeviceError, match="halfway"):
        cell.move_to(target)
    assert math.isclose(cell.angle, motion.angle)  # the plate did turn
    middle = interpolate(start_arm, motion.T_base_camera, 0.5)
    assert np.allclose(cell.arm.pose.translation, middle.translation)
    assert not np.allclose(cell.arm.pose.translation, motion.T_base_camera.translation, atol=1e-3)
    assert not np.allclose(cell.arm.pose.translation, start_arm.translation, atol=1e-3)
    assert start_angle != cell.angle
    cell.move_to(target)  # the retry reaches it
    assert np.allclose(cell.pose.translation, target.translation)


def test_turntable_error_leaves_the_plate_and_the_arm(mesh) -> None:
    cell, _ = faulty_cell(mesh, turntable_error=1.0)
    angle, arm = cell.angle, cell.arm.pose.translation.copy()
    with pytest.raises(DeviceError, match="turntable"):
        cell.move_to(Pose.look_at([0.3, 0.25, 0.3], [0, 0, 0.08]))
    assert cell.angle == angle and np.array_equal(cell.arm.pose.translation, arm)


def test_bad_frames(mesh) -> None:
    cell, _ = faulty_cell(mesh, schedule=[{"kind": "nan_frame", "at": 1}, {"kind": "empty_frame", "at": 2}])
    with pytest.raises(ValueError, match="non-finite"):
        cell.capture()
    assert not cell.capture().valid.any()
    assert cell.capture().valid.sum() > 1000


def test_camera_timeout_hangs_until_released(mesh) -> None:
    cell, injector = faulty_cell(mesh, camera_timeout=1.0)
    t0 = time.perf_counter()
    with pytest.raises(DeviceTimeoutError, match=r"within 0\.2 s"):
        call_with_timeout(cell.capture, 0.2, "camera capture")
    assert 0.2 <= time.perf_counter() - t0 < 2.0
    threading.Timer(0.1, injector.release).start()
    with pytest.raises(CaptureError, match="simulated hang"):
        cell.capture()  # no deadline: it hangs until the session releases it


def test_fail_next_still_reaches_the_wrapped_device(mesh) -> None:
    cell, _ = faulty_cell(mesh)
    cell.arm.fail_next = DeviceError("stalled")
    assert cell.arm.inner.fail_next is not None and cell.arm.moves == 0
    with pytest.raises(DeviceError, match="stalled"):
        cell.move_to(cell.initial_pose())


def test_call_with_timeout_passes_values_and_errors() -> None:
    assert call_with_timeout(lambda: 3, 1.0, "x") == 3
    assert call_with_timeout(lambda: 4, None, "x") == 4

    def boom() -> None:
        raise CaptureError("no image")

    with pytest.raises(CaptureError, match="no image"):
        call_with_timeout(boom, 1.0, "x")


def test_frame_files_round_trip_and_refuse_damage(tmp_path: Path) -> None:
    k = Intrinsics(8, 6, 10.0, 10.0, 3.5, 2.5)
    depth = np.linspace(0.0, 1.0, 48, dtype=np.float32).reshape(6, 8)
    frame = DepthFrame(depth, Pose.look_at([0.5, 0, 0.3], [0, 0, 0]), k)
    digest = save_frame(tmp_path / "f.npz", frame)
    back = load_frame(tmp_path / "f.npz", digest)
    assert np.array_equal(back.depth, depth) and back.intrinsics == k
    assert np.allclose(back.T_world_camera.matrix, frame.T_world_camera.matrix)
    assert not list(tmp_path.glob(".*part"))  # written through a temp name, then renamed
    with pytest.raises(ValueError, match="checksum"):
        load_frame(tmp_path / "f.npz", "0" * 64)
    (tmp_path / "g.npz").write_bytes(b"garbage")
    with pytest.raises(ValueError, match="not a frame file"):
        load_frame(tmp_path / "g.npz")
    bad = dict(np.load(tmp_path / "f.npz"))
    bad["depth"] = np.full((6, 8), np.nan, np.float32)
    np.savez(tmp_path / "nan.npz", **bad)
    with pytest.raises(ValueError, match="non-finite"):
        load_frame(tmp_path / "nan.npz")
    with pytest.raises(ValueError, match="cannot read"):
        load_frame(tmp_path / "missing.npz")
