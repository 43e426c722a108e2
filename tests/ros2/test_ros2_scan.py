"""A supervised scan through the REST API on the ``ros2`` cell, against the fake ROS 2 cell process over DDS.

The fake cell (``tests/ros2/fake_cell.py``) renders the object at the pose its joints and plate put the camera, so
the session sees the views it asks for; each device fault it can simulate ends the session in ``error`` with a
message naming the cause, the journal keeps every capture taken before, and the session resumes on a new server.
"""

from __future__ import annotations

import dataclasses
import math
import time
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from fastapi.testclient import TestClient

from app.main import create_app
from app.settings import AppSettings
from devices.config import CellConfig, DeviceConfig
from devices.hwcell import HardwareCell
from planner import PlannerConfig
from planner.types import Pose
from tests.helpers import SMALL as SMALL_PLANNER
from tests.ros2.fakecell import CAMERA, FAST_ARM, FakeRos2Cell, fake_ros2_cell
from workbench.journal.store import read_journal, sessions_dir

BASE_URL = "http://127.0.0.1"


SETTLE = "settle_s = 0.05"
"""The arm's and the plate's settle time in these tests' cell file (the drivers' default is 0.2 s): the fake cell
holds still once at the goal, so a quarter of the default still captures where it settled (the captured poses are
checked against the requested ones below), in less waiting per move."""


@pytest.fixture(scope="module")
def cell(tmp_path_factory: pytest.TempPathFactory) -> Iterator[FakeRos2Cell]:
    with fake_ros2_cell(
        tmp_path_factory.mktemp("ros2cell"), arm=f"timeout_margin_s = 1.5\n{SETTLE}", turntable=SETTLE, table_scale=4.0
    ) as fake:
        yield fake


@pytest.fixture
def fresh(cell: FakeRos2Cell) -> Iterator[FakeRos2Cell]:
    cell.command("reset")
    yield cell
    cell.command("reset")


def settings(tmp: Path, cell: FakeRos2Cell, name: str) -> AppSettings:
    return AppSettings(
        viser_port=0,
        scene=False,
        data_dir=tmp / name,
        cell=str(cell.path),
        devices=DeviceConfig(camera=CAMERA, cell=CellConfig(arm=FAST_ARM)),
        planner=PlannerConfig().replace(**SMALL_PLANNER),
    )


def close(a: Pose, b: Pose, metres: float, degrees: float) -> bool:
    dt = float(np.linalg.norm(a.translation - b.translation))
    cos = (np.trace(a.rotation.T @ b.rotation) - 1) / 2
    return dt <= metres and math.degrees(math.acos(max(-1.0, min(1.0, float(cos))))) <= degrees


def approve_best(c: TestClient, sid: str) -> Any:
    plan = c.post(f"/api/sessions/{sid}/plan").json()
    assert plan["best"] is not None, plan
    return c.post(f"/api/sessions/{sid}/approve", json={"plan_id": plan["plan_id"], "index": plan["best"]["index"]})


APPROVED = 3
"""Views approved after the first in the supervised scan (each a real-time move of the fake arm and its plate, then
a capture): enough for the map to cover the object, every capture checked where the arm settled."""


@pytest.mark.slow
def test_supervised_scan_over_ros2_and_resume(tmp_path: Path, fresh: FakeRos2Cell) -> None:
    s = settings(tmp_path, fresh, "scan")
    with TestClient(create_app(s), base_url=BASE_URL) as c:
        r = c.post("/api/sessions", json={"seed": 0, "source": {"kind": "hardware", "truth": "l-block"}})
        assert r.status_code == 201, r.text
        sid = r.json()["id"]
        cell = c.app.state.registry.get(sid).cell  # type: ignore[attr-defined]
        assert isinstance(cell, HardwareCell) and cell.rig is not None
        assert type(cell.rig.arm).__name__ == "Ros2Arm" and type(cell.rig.camera).__name__ == "Ros2Camera"
        # the intrinsics came from the fake's CameraInfo
        assert cell.rig.camera.intrinsics == CAMERA.intrinsics
        assert c.post(f"/api/sessions/{sid}/capture").status_code == 200
        for _ in range(APPROVED):
            r = approve_best(c, sid)
            assert r.status_code == 200, r.text
        status = c.get(f"/api/sessions/{sid}").json()
        assert status["iteration"] == 1 + APPROVED and status["error"] in (None, ""), status
        assert status["coverage"] > 0.3, status["coverage"]
        journal = read_journal(sessions_dir(s.data_dir) / sid)
        caps = journal.of_kind("capture")
        assert len(caps) == 1 + APPROVED
        for event in caps:
            # where the fake cell's joints put the camera: where the planner asked (a settled arm, not mid-move)
            assert close(Pose.from_dict(event["pose"]), Pose.from_dict(event["requested_pose"]), 2e-3, 0.3)
            frame = journal.frame(event)
            assert frame.depth.shape == (120, 160) and int(np.count_nonzero(frame.depth)) > 500
            # 16UC1 millimetres: every depth a whole number of mm
            valid = frame.depth[frame.depth > 0].astype(np.float64)
            assert np.allclose(valid * 1000.0, np.round(valid * 1000.0), atol=1e-3)
        q_end = cell.rig.arm.joint_positions()
        assert np.allclose(caps[-1]["device_state"]["arm"]["q"], q_end, atol=1e-3)

    # a new server: the session is interrupted, resumes on the reopened ros2 devices, and scans on
    with TestClient(create_app(s), base_url=BASE_URL) as c:
        assert c.get(f"/api/sessions/{sid}").json()["state"] == "interrupted"
        r = c.post(f"/api/sessions/{sid}/resume")
        assert r.status_code == 200, r.text
        cell = c.app.state.registry.get(sid).cell  # type: ignore[attr-defined]
        assert np.allclose(cell.rig.arm.joint_positions(), q_end, atol=1e-3)  # resuming moved nothing
        r = approve_best(c, sid)
        assert r.status_code == 200, r.text
        assert c.get(f"/api/sessions/{sid}").json()["iteration"] == 2 + APPROVED
        assert c.delete(f"/api/sessions/{sid}").status_code in (200, 204)


FAULTS = [
    ("ignore_trajectory", "too slow"),
    ("jump", "deviation from the path"),
    ("silent_camera", "no complete depth image"),
    ("encoding rgb8", "is not a depth encoding"),
    ("silent_joints", "joint states silent"),
]
"""Each fault the fake cell simulates and the words of the session's error."""


@pytest.mark.slow
def test_each_device_fault_ends_in_error_and_the_session_goes_on(tmp_path: Path, fresh: FakeRos2Cell) -> None:
    s = settings(tmp_path, fresh, "fault")
    with TestClient(create_app(s), base_url=BASE_URL) as c:
        r = c.post("/api/sessions", json={"seed": 0, "source": {"kind": "hardware", "truth": "l-block"}})
        assert r.status_code == 201, r.text
        sid = r.json()["id"]
        assert c.post(f"/api/sessions/{sid}/capture").status_code == 200
        camera = c.app.state.registry.get(sid).cell.rig.camera  # type: ignore[attr-defined]
        waits = camera.config
        for fault, words in FAULTS:
            plan = c.post(f"/api/sessions/{sid}/plan").json()
            assert plan["best"] is not None, plan
            fresh.command(fault)  # while the arm moves to the planned view
            # a silent camera is waited for its timeout: a short one here (the same wait as the cell file's 3 s)
            camera.config = dataclasses.replace(waits, timeout_s=0.5) if fault == "silent_camera" else waits
            r = c.post(
                f"/api/sessions/{sid}/approve", json={"plan_id": plan["plan_id"], "index": plan["best"]["index"]}
            )
            camera.config = waits
            assert r.status_code == 503, (fault, r.text)
            status = c.get(f"/api/sessions/{sid}").json()
            assert status["state"] == "error", status
            assert words in status["error"], (fault, status["error"])
            assert status["iteration"] == 1  # the map is the first view's: nothing half-taken was added
            journal = read_journal(sessions_dir(s.data_dir) / sid)
            assert words in journal.of_kind("error")[-1]["message"]
            fresh.command("reset")
        # silent joint states when planning: the plan cannot start from the arm's joints; error, nothing changed
        fresh.command("silent_joints")
        arm = c.app.state.registry.get(sid).cell.rig.arm  # type: ignore[attr-defined]
        deadline = time.monotonic() + 10.0  # the last joint state heard must be older than the arm's limit
        while (arm.states.age() or 0.0) <= arm.config.state_timeout_s and time.monotonic() < deadline:
            time.sleep(0.02)
        r = c.post(f"/api/sessions/{sid}/plan")
        assert r.status_code == 503 and "joint states silent" in r.json()["detail"], r.text
        status = c.get(f"/api/sessions/{sid}").json()
        assert status["state"] == "error" and "joint states silent" in status["error"], status
        fresh.command("reset")
        heard = arm.states.count
        assert arm.states.wait(lambda m: arm.states.count > heard, 3.0) is not None  # the joints speak again
        # the devices are well again: a new plan from where the arm is now, and the scan goes on
        r = approve_best(c, sid)
        assert r.status_code == 200, r.text
        status = c.get(f"/api/sessions/{sid}").json()
        assert status["state"] != "error" and status["iteration"] == 2, status
        assert len(read_journal(sessions_dir(s.data_dir) / sid).of_kind("capture")) == 2
