"""A supervised scan through the REST API on hardware drivers: the RealSense driver playing a recording, the fake
UR controller and the fake GRBL firmware (tests/devices/drivers/rigfixtures.py).

The recording is written from a dry run of the same scan (``"dry_run": true``: the simulator on the cell file's
arm model, no device opened), so the hardware session sees the depth images of the views it is asked to take.
"""

from __future__ import annotations

import dataclasses
import math
import threading
import time
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from fastapi.testclient import TestClient

from app.main import create_app
from app.settings import AppSettings
from devices.cell import rz
from devices.cellfile import load_cell_file
from devices.config import CameraConfig, DeviceConfig
from devices.drivers.limits import JointLimits
from devices.drivers.rsrecord import write_depth_recording
from devices.faults import FaultConfig
from devices.hwcell import HardwareCell
from devices.planner_noise import planner_config_for
from nbv.cli import main
from planner import PlannerConfig
from planner.types import Pose
from tests.devices.drivers.rigfixtures import cell_toml, fake_hardware_cell, play_fast
from tests.devices.drivers.rsfixtures import DEPTH_UNIT, rendered_views
from tests.helpers import SMALL as SMALL_PLANNER
from workbench.journal.store import read_journal, sessions_dir
from workbench.session.session import STOP_WAIT

BASE_URL = "http://127.0.0.1"
VIEWS = 3
"""Views approved after the first capture."""
CAMERA = CameraConfig(width=160, height=120, fx=140.0, fy=140.0, cx=79.5, cy=59.5, min_depth=0.05, max_depth=3.0)
"""A small camera (small recordings) that still sees the object well from every candidate."""


def fast_cell(port: str, allow_auto: bool = False) -> str:
    """The fixture's cell file with an arm quick enough for a test (85 deg/s, a cap below the URDF's 90, at full
    fraction, 1440 deg/s^2; the fixture's fake controller plays it faster still, :func:`play_fast`)."""
    k = CAMERA.intrinsics
    text = cell_toml(
        port,
        k,
        arm_speed="max_joint_speed_deg = 85\nspeed_fraction = 1.0\nacceleration_fraction = 1.0\n"
        "max_joint_acceleration_deg = 1440",
    )
    return text.replace("allow_auto = false", f"allow_auto = {'true' if allow_auto else 'false'}")


def app_settings(tmp: Path, cell: Path, name: str, **kw: Any) -> AppSettings:
    devices = DeviceConfig(camera=CAMERA)
    return AppSettings(
        viser_port=0, scene=False, data_dir=tmp / name, cell=str(cell), devices=devices, planner=_planner(), **kw
    )


def _planner() -> Any:
    from planner import PlannerConfig

    return PlannerConfig().replace(**SMALL_PLANNER)


def pose_of(d: dict[str, Any]) -> Pose:
    return Pose.from_dict(d)


def close(a: Pose, b: Pose, metres: float, degrees: float) -> bool:
    dt = float(np.linalg.norm(a.translation - b.translation))
    cos = (np.trace(a.rotation.T @ b.rotation) - 1) / 2
    angle = math.degrees(math.acos(max(-1.0, min(1.0, float(cos)))))
    return dt <= metres and angle <= degrees


def captures(data: Path, sid: str) -> tuple[Any, list[dict[str, Any]]]:
    journal = read_journal(sessions_dir(data) / sid)
    return journal, [e for e in journal.of_kind("capture")]


@pytest.fixture
def rig(tmp_path: Path):
    depths, k = rendered_views(2, CAMERA)  # placeholders: the dry run's frames replace them before the devices open
    with fake_hardware_cell(tmp_path, depths, k, depth_unit=DEPTH_UNIT) as fake:
        fake.path.write_text(fast_cell(fake.grbl.port))
        play_fast(fake)  # where the arm and plate go is checked here, not how long they take
        yield fake


def dry_run_scan(tmp: Path, rig: Any) -> tuple[list[Any], list[Pose], float]:
    """A dry run of the scan, approving the planner's choices: (its depth frames, the captured poses, coverage)."""
    with TestClient(create_app(app_settings(tmp, rig.path, "dry")), base_url=BASE_URL) as c:
        r = c.post("/api/sessions", json={"seed": 0, "source": {"kind": "hardware", "dry_run": True}})
        assert r.status_code == 201, r.text
        sid = r.json()["id"]
        assert c.post(f"/api/sessions/{sid}/capture").status_code == 200
        for _ in range(VIEWS):
            plan = c.post(f"/api/sessions/{sid}/plan").json()
            assert plan["best"] is not None, plan
            best = plan["best"]["index"]
            r = c.post(f"/api/sessions/{sid}/approve", json={"plan_id": plan["plan_id"], "index": best})
            assert r.status_code == 200, r.text
        status = c.get(f"/api/sessions/{sid}").json()
        journal, caps = captures(tmp / "dry", sid)
        assert journal.header["source"] == {"kind": "hardware", "cell": str(rig.path), "dry_run": True, "truth": None}
        frames = [journal.frame(e) for e in caps]
        poses = [pose_of(e["pose"]) for e in caps]
    # a dry run opens no device and moves nothing
    assert not [call for call in rig.controller.calls if call[0] in ("moveJ", "servoJ")]
    assert rig.controller.q[1] == pytest.approx(-1.57)
    return frames, poses, float(status["coverage"])


@pytest.mark.slow
def test_supervised_scan_on_hardware_drivers(tmp_path: Path, rig: Any) -> None:
    frames, dry_poses, dry_coverage = dry_run_scan(tmp_path, rig)
    assert len(frames) == VIEWS + 1 and dry_coverage > 0.2
    k = CAMERA.intrinsics
    write_depth_recording(tmp_path / "scan.db3", [f.depth for f in frames], k, depth_unit=DEPTH_UNIT)

    settings = app_settings(tmp_path, rig.path, "hw")
    with TestClient(create_app(settings), base_url=BASE_URL) as c:
        r = c.post("/api/sessions", json={"seed": 0, "source": {"kind": "hardware", "truth": "l-block"}})
        assert r.status_code == 201, r.text
        sid = r.json()["id"]
        session = c.app.state.registry.get(sid)  # type: ignore[attr-defined]
        cell = session.cell
        assert isinstance(cell, HardwareCell) and cell.rig is not None
        # the arm model comes from the cell file: the hand-eye transform and the joint speed limit
        assert cell.kinematics is not None
        assert np.allclose(np.array(cell.kinematics.config.T_flange_camera)[:3, 3], [0.0, 0.0, 0.05])
        assert cell.kinematics.config.base == (-0.85, 0.0, 0.0)
        assert float(np.max(cell.kinematics.model.velocity)) <= math.radians(85.0)

        # a second session cannot take the same devices
        r2 = c.post("/api/sessions", json={"seed": 0})
        assert r2.status_code == 409 and "in use" in r2.json()["detail"]

        assert c.post(f"/api/sessions/{sid}/capture").status_code == 200, "first capture"
        moves = sum(1 for call in rig.controller.calls if call[0] == "moveJ")
        assert moves == 1  # the first view: the arm went from its home to the initial view
        for dry in dry_poses[1:]:
            # the person approves the view the dry run took: its recorded frame was rendered there (the plans
            # differ a little: a frame quantised to the depth unit can move the map's box by a voxel)
            plan = c.post(f"/api/sessions/{sid}/plan").json()
            assert plan["n_eligible"] > 0 and plan["best"] is not None
            body = {"plan_id": plan["plan_id"], "pose": dry.to_dict()}
            r = c.post(f"/api/sessions/{sid}/approve", json=body)
            assert r.status_code == 200, r.text
        status = c.get(f"/api/sessions/{sid}").json()
        assert status["iteration"] == VIEWS + 1
        journal, caps = captures(settings.data_dir, sid)
        assert len(caps) == VIEWS + 1
        # poses: forward kinematics of the fake UR's joints (read from the controller itself), plate turned by GRBL
        last = caps[-1]
        q = np.array(rig.controller.q, dtype=np.float64)
        theta = math.radians(float(rig.grbl.position))
        T_expected = rz(-theta) @ cell.kinematics.camera_pose(q)
        assert close(pose_of(last["pose"]), T_expected, 1e-3, 0.2)
        assert np.allclose(last["device_state"]["arm"]["q"], q, atol=1e-3)
        # ... each where it was asked to be: the view the dry run took there
        for event, dry in zip(caps, dry_poses, strict=True):
            assert close(pose_of(event["pose"]), pose_of(event["requested_pose"]), 2e-3, 0.2)
            assert close(pose_of(event["pose"]), dry, 2e-3, 0.2)
        # coverage of the played-back frames: the dry run's, within the depth unit's effect
        assert status["coverage"] == pytest.approx(dry_coverage, abs=0.02)
        assert status["coverage"] > 0.2

        # no step or auto without allow_auto; nothing moves
        for path in ("step", "auto"):
            r = c.post(f"/api/sessions/{sid}/{path}", json={"count": 1})
            assert r.status_code == 409 and "allow_auto" in r.json()["detail"], r.text
        assert sum(1 for call in rig.controller.calls if call[0] == "moveJ") == moves + VIEWS

        # speed and joint limits are checked before a trajectory is sent; the refusal is the session's error
        plan = c.post(f"/api/sessions/{sid}/plan").json()
        best = plan["best"]["index"]
        arm = cell.rig.arm  # the driver itself (the session's cell.arm is wrapped for fault injection)
        limits = arm._limits
        q_now = arm.joint_positions()
        arm._limits = JointLimits(
            tuple(q_now - 1e-3), tuple(q_now + 1e-3), limits.max_speed, limits.max_acceleration
        )  # nowhere to go
        r = c.post(f"/api/sessions/{sid}/approve", json={"plan_id": plan["plan_id"], "index": best})
        assert r.status_code == 503, r.text
        error = c.get(f"/api/sessions/{sid}").json()["error"]
        assert "limits:" in error and ("is above its bound" in error or "is below its bound" in error), error
        assert sum(1 for call in rig.controller.calls if call[0] == "moveJ") == moves + VIEWS
        arm._limits = limits

        # stop halts a move in flight: arm and turntable stop, the session goes to error with the joints
        answer: dict[str, Any] = {}

        def approve() -> None:
            answer["r"] = c.post(f"/api/sessions/{sid}/approve", json={"plan_id": plan["plan_id"], "index": best})

        # the controller holds the move 0.05 s in (the arm has left the view, the move runs on until stopped): the
        # stop finds it in flight however late a loaded machine serves the request (a stop after the move's end
        # has no move to halt and answers at once, in the approval's busy state while it captures)
        rig.controller.hold_after_s = 0.05
        thread = threading.Thread(target=approve)
        thread.start()
        deadline = time.monotonic() + 20
        while not rig.controller.holding:
            assert time.monotonic() < deadline and thread.is_alive(), "the arm never started"
            time.sleep(0.01)
        asked = time.monotonic()
        r = c.post(f"/api/sessions/{sid}/stop")
        waited = time.monotonic() - asked
        thread.join(20)
        assert r.status_code == 200, r.text
        # the stop answers once the session is in error, or after STOP_WAIT s (a busy machine's slow devices)
        assert r.json()["state"] == "error" or waited >= STOP_WAIT, (waited, r.text)
        assert answer["r"].status_code == 503
        status = c.get(f"/api/sessions/{sid}").json()
        assert status["state"] == "error", status
        error = status["error"]
        assert "stopped on request" in error and "last joints" in error, error
        assert ("stopJ", 2.0, False) in rig.controller.calls or any(call[0] == "stopJ" for call in rig.controller.calls)
        journal, _ = captures(settings.data_dir, sid)
        assert "last joints" in journal.of_kind("error")[-1]["message"]
        halted = np.array(rig.controller.q)
        assert not np.allclose(halted, q, atol=1e-3)  # it had left the last view
        time.sleep(0.3)
        assert np.allclose(rig.controller.q, halted)  # and stays where it stopped

    # the server stopped: the session is interrupted; a new server resumes it and reopens the devices
    calls = len(rig.controller.calls)
    with TestClient(create_app(settings), base_url=BASE_URL) as c:
        assert c.get(f"/api/sessions/{sid}").json()["state"] == "interrupted"
        r = c.post(f"/api/sessions/{sid}/resume")
        assert r.status_code == 200, r.text
        cell = c.app.state.registry.get(sid).cell  # type: ignore[attr-defined]
        assert isinstance(cell, HardwareCell) and cell.rig is not None
        assert len(rig.controller.calls) > calls  # connected again
        assert np.allclose(rig.controller.q, halted)  # resuming moved nothing
        assert c.delete(f"/api/sessions/{sid}").status_code in (200, 204)
        r = c.post("/api/sessions", json={"seed": 0})  # the devices are free again
        assert r.status_code == 201, r.text


def test_step_runs_when_the_cell_file_allows_auto(tmp_path: Path, rig: Any) -> None:
    rig.path.write_text(fast_cell(rig.grbl.port, allow_auto=True))
    with TestClient(create_app(app_settings(tmp_path, rig.path, "dry")), base_url=BASE_URL) as c:
        sid = c.post("/api/sessions", json={"seed": 0, "source": {"kind": "hardware", "dry_run": True}}).json()["id"]
        assert c.post(f"/api/sessions/{sid}/capture").status_code == 200
        assert c.post(f"/api/sessions/{sid}/step", json={"count": 1}).status_code == 200
        journal, caps = captures(tmp_path / "dry", sid)
        depths = [journal.frame(e).depth for e in caps]
    write_depth_recording(tmp_path / "scan.db3", depths, CAMERA.intrinsics, depth_unit=DEPTH_UNIT)
    with TestClient(create_app(app_settings(tmp_path, rig.path, "auto")), base_url=BASE_URL) as c:
        sid = c.post("/api/sessions", json={"seed": 0}).json()["id"]  # the default source: the cell file's devices
        assert c.post(f"/api/sessions/{sid}/capture").status_code == 200
        r = c.post(f"/api/sessions/{sid}/step", json={"count": 1})
        assert r.status_code == 200, r.text
        assert r.json()["iteration"] == 2
        assert sum(1 for call in rig.controller.calls if call[0] == "moveJ") == 2


def test_bad_cell_file_is_one_line_naming_the_field(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    bad = tmp_path / "bad.toml"
    bad.write_text('[devices.arm]\ndriver = "ur"\nhost = "x"\nspeed_fraction = 2.0\n')
    assert main(["serve", "--cell", str(bad), "--port", "0"]) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and "devices.arm.speed_fraction" in err
    assert main(["serve", "--dry-run", "--port", "0"]) == 2
    assert "server.dry_run" in capsys.readouterr().err
    # the REST API: 422 naming the field, and nothing created
    settings = dataclasses.replace(app_settings(tmp_path, bad, "bad"))
    with TestClient(create_app(settings), base_url=BASE_URL) as c:
        r = c.post("/api/sessions", json={"seed": 0})
        assert r.status_code == 422 and "devices.arm.speed_fraction" in r.json()["detail"], r.text
        assert c.get("/api/sessions").json() == [] or c.get("/api/sessions").json().get("sessions") == []
        r = c.post("/api/sessions", json={"source": {"kind": "hardware", "cell": "/etc/passwd"}})
        assert r.status_code == 422  # requests never name a path


def test_simulated_faults_never_reach_the_real_devices(tmp_path: Path, rig: Any) -> None:
    """The server's [faults] (every capture fails) apply to simulated sessions only: a hardware session leaves
    them out (its captures work, its journal says none), refuses a request's own faults (422, the devices not
    taken), and the test route cannot queue one into it."""
    fail = FaultConfig(capture_failure=1.0)
    settings = app_settings(tmp_path, rig.path, "faults", faults=fail, fault_api=True)
    with TestClient(create_app(settings), base_url=BASE_URL) as c:
        hardware = {"kind": "hardware", "truth": "l-block"}
        r = c.post("/api/sessions", json={"seed": 0, "source": hardware, "faults": {"capture_failure": 1.0}})
        assert r.status_code == 422 and "simulated devices only" in r.json()["detail"], r.text
        r = c.post("/api/sessions", json={"seed": 0, "source": hardware})  # the devices are free
        assert r.status_code == 201, r.text
        sid = r.json()["id"]
        assert c.post(f"/api/sessions/{sid}/capture").status_code == 200  # no injected failure
        r = c.post(f"/api/sessions/{sid}/faults", json={"kind": "capture_failure"})
        assert r.status_code == 409 and "do not inject" in r.json()["detail"]
        header = read_journal(sessions_dir(settings.data_dir) / sid).header
        assert header["faults"] == FaultConfig().to_dict()
        c.delete(f"/api/sessions/{sid}")
        sim = c.post("/api/sessions", json={"seed": 0, "source": {"kind": "sim"}, "config": SMALL_PLANNER}).json()
        r = c.post(f"/api/sessions/{sim['id']}/capture")
        assert r.status_code == 503 and "capture" in r.json()["detail"], r.text  # a simulated one fails as told


def test_simulated_sensor_errors_never_reach_the_real_camera(tmp_path: Path, rig: Any) -> None:
    """A request's sensor or calibration model is refused for the real devices (422, the devices not taken), and
    the server's default simulated sensor is left out of a hardware session: its journal says ideal / none and its
    planner config has no simulated noise."""
    devices = DeviceConfig(camera=dataclasses.replace(CAMERA, sensor="realsense-d435", calibration="typical"))
    settings = dataclasses.replace(app_settings(tmp_path, rig.path, "sensor"), devices=devices)
    with TestClient(create_app(settings), base_url=BASE_URL) as c:
        hardware = {"kind": "hardware", "truth": "l-block"}
        r = c.post("/api/sessions", json={"seed": 0, "source": hardware, "camera": {"sensor": "realsense-d435"}})
        assert r.status_code == 422 and "real camera" in r.json()["detail"], r.text
        r = c.post("/api/sessions", json={"seed": 0, "source": hardware})  # the devices are free
        assert r.status_code == 201, r.text
        header = read_journal(sessions_dir(settings.data_dir) / r.json()["id"]).header
        camera = header["devices"]["camera"]
        assert (camera["sensor"], camera["calibration"]) == ("ideal", "none")
        assert header["config"]["noise"]["depth_z2"] == 0 and header["config"]["noise"]["fit_plate"] is False


def test_the_planner_assumes_the_noise_the_cell_file_names_for_its_camera(tmp_path: Path, rig: Any) -> None:
    """A real camera's images are its own, but the planner's plate band, ICP gate and candidate settings follow the
    ``noise_model`` of the cell file's camera (the same as for that simulated sensor); without one, a perfect
    sensor's; an unknown name is refused naming the field."""
    ideal = PlannerConfig().replace(**SMALL_PLANNER)

    def header_of_a_session(name: str) -> dict[str, Any]:
        with TestClient(create_app(app_settings(tmp_path, rig.path, name)), base_url=BASE_URL) as c:
            r = c.post("/api/sessions", json={"seed": 0, "source": {"kind": "hardware"}})
            assert r.status_code == 201, r.text
            sid = r.json()["id"]
            header = read_journal(sessions_dir(tmp_path / name) / sid).header
            assert c.delete(f"/api/sessions/{sid}").status_code in (200, 204)
        return header

    header = header_of_a_session("perfect")
    assert header["devices"]["camera"]["sensor"] == "ideal"
    assert PlannerConfig.from_dict(header["config"]).noise == ideal.noise

    text = rig.path.read_text()
    rig.path.write_text(text.replace('driver = "realsense"', 'driver = "realsense"\nnoise_model = "realsense-d435"'))
    header = header_of_a_session("d435")
    assert header["devices"]["camera"]["sensor"] == "realsense-d435"
    config = PlannerConfig.from_dict(header["config"])
    expected = planner_config_for(ideal, dataclasses.replace(CAMERA, sensor="realsense-d435"))
    assert config.noise == expected.noise and config.noise.depth_z2 > 0  # the D435's range-dependent noise
    assert config.candidates == expected.candidates and config.candidates.aim == "content"

    rig.path.write_text(text.replace('driver = "realsense"', 'driver = "realsense"\nnoise_model = "kinect"'))
    with pytest.raises(ValueError, match=r"devices\.camera\.noise_model: one of ideal, realsense-d435"):
        load_cell_file(rig.path)
