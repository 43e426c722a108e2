"""``nbv devices check`` and ``open_rig`` on a cell of the RealSense recording, the fake UR and the fake GRBL.

The cell comes from ``rigfixtures.fake_hardware_cell``: the camera plays a recording written by
librealsense (rendered by the simulated camera); the turntable is the fake GRBL firmware on a pseudo
terminal (a real serial device to pyserial, so it also works from a subprocess); the UR driver talks to
the in-process controller of ``fake_ur`` through ``registry.override`` (the cell file says
``driver = "ur"`` like a lab's; only the RTDE classes differ), so those tests run the CLI in-process.
"""

from __future__ import annotations

import json
import math
import os
import subprocess
import sys
import threading
from pathlib import Path

import numpy as np
import pytest

from devices.cellfile import load_cell_file
from devices.drivers.common import ArmFaultError
from devices.drivers.ur import UR_JOINTS
from devices.protocols import DeviceError
from devices.rig import open_rig
from devices.trajectory import JointTrajectory
from nbv.cli import main
from planner.types import DepthFrame, Pose
from tests.devices.drivers.fake_grbl import FakeGrbl
from tests.devices.drivers.fake_ur import CONTROLLERS
from tests.devices.drivers.rigfixtures import UR_HOST, cell_toml, fake_hardware_cell
from tests.devices.drivers.rsfixtures import DEPTH_UNIT, record_views, rendered_views

ROOT = Path(__file__).resolve().parents[3]


@pytest.fixture
def cell(tmp_path):
    """(cell file path, rendered depths, fake GRBL, fake UR controller)."""
    depths, k = rendered_views(3)
    with fake_hardware_cell(tmp_path, depths, k) as fake:
        yield fake.path, depths, fake.grbl, fake.controller


def test_devices_check_prints_one_ok_line_per_device(cell, capsys):
    path, _, _, controller = cell
    assert main(["devices", "check", "--config", str(path)]) == 0
    lines = capsys.readouterr().out.strip().splitlines()
    assert len(lines) == 4
    assert lines[0].split()[:3] == ["camera", "realsense", "ok"]
    assert "80x60" in lines[0] and "test capture" in lines[0]
    assert lines[1].split()[:3] == ["arm", "ur", "ok"] and "UR at ur-cell" in lines[1] and "-90.0" in lines[1]
    assert lines[2].split()[:3] == ["turntable", "grbl", "ok"] and "Grbl 1.1h" in lines[2] and "0.00 deg" in lines[2]
    assert lines[3] == "3 of 3 devices ok"
    assert ("stopScript",) in controller.calls  # each device was closed after its check


def silent_turntable(path: Path, grbl: FakeGrbl) -> None:
    """Make the cell's GRBL silent, and the cell file wait 0.5 s for its banner instead of the default 3 s: no
    banner ever comes, so the wait is all the check spends on it (3 s each time, the machine otherwise idle)."""
    grbl.silent = True
    text = path.read_text()
    assert "[devices.turntable]\n" in text
    path.write_text(text.replace("[devices.turntable]\n", "[devices.turntable]\nstartup_s = 0.5\n"))


def test_devices_check_reports_each_failure_and_exits_1(cell, capsys):
    path, _, grbl, controller = cell
    silent_turntable(path, grbl)
    controller.safety_mode = 3  # connecting works; the arm's state is readable even in a protective stop
    assert main(["devices", "check", "--config", str(path)]) == 1
    lines = capsys.readouterr().out.strip().splitlines()
    assert lines[0].split()[2] == "ok"
    assert lines[1].split()[2] == "ok"
    assert lines[2].split()[:3] == ["turntable", "grbl", "FAILED"]
    assert "DeviceTimeoutError: turntable: no answer from GRBL" in lines[2] and "(no Grbl banner)" in lines[2]
    assert lines[3] == "2 of 3 devices ok; 1 failed"
    CONTROLLERS.pop(UR_HOST)
    assert main(["devices", "check", "--config", str(path)]) == 1
    lines = capsys.readouterr().out.strip().splitlines()
    assert lines[1].split()[:3] == ["arm", "ur", "FAILED"] and "Connection refused" in lines[1]


def test_a_bad_cell_file_is_one_error_line_and_exit_2(tmp_path, capsys):
    path = tmp_path / "cell.toml"
    path.write_text('[devices.arm]\ndriver = "ur"\nhost = "x"\nspeed_fraction = 3\n')
    assert main(["devices", "check", "--config", str(path)]) == 2
    err = capsys.readouterr().err.strip()
    assert err == "nbv: error: devices.arm.speed_fraction: must be in (0, 1], got 3.0"


def test_the_cli_in_a_subprocess_checks_the_recording_and_the_serial_turntable(tmp_path):
    path, _, k = record_views(tmp_path, n=1)
    with FakeGrbl() as grbl:
        path = tmp_path / "cell.toml"
        path.write_text(cell_toml(grbl.port, k, arm=False))
        env = {**os.environ, "PYTHONPATH": str(ROOT)}
        out = subprocess.run(
            [sys.executable, "-m", "nbv.cli", "devices", "check", "--config", str(path)],
            capture_output=True,
            text=True,
            env=env,
            timeout=120,
        )
    assert out.returncode == 0, out.stderr
    assert out.stdout.strip().splitlines()[-1] == "2 of 2 devices ok"


def test_open_rig_drives_the_cell_and_stop_halts_arm_and_turntable(cell):
    path, depths, grbl, controller = cell
    with open_rig(load_cell_file(path)) as rig:
        frame = rig.camera.capture()
        assert np.max(np.abs(frame.depth - depths[0])) <= DEPTH_UNIT
        rig.turntable.rotate_to(math.pi / 4)
        assert grbl.position == 45.0
        q0 = rig.arm.joint_positions()
        goal = q0 + np.radians([40, 0, 0, 0, 0, 0])  # 1.33 s at 30 deg/s, stopped after 0.2 s
        t = np.linspace(0, 1, 11)
        traj = JointTrajectory(UR_JOINTS, t, q0 + t[:, None] * (goal - q0), np.zeros((11, 6)))
        timer = threading.Timer(0.2, rig.stop)
        timer.start()
        with pytest.raises(ArmFaultError, match="stopped on request"):
            rig.arm.execute(traj)
        timer.join()
        assert 1.0 < math.degrees(rig.arm.joint_positions()[0] - q0[0]) < 38.0
        assert np.allclose(rig.cell.hand_eye.translation, [0, 0, 0.05])
    assert ("stopScript",) in controller.calls


def test_open_rig_closes_what_it_opened_when_a_device_fails(cell):
    path, _, grbl, controller = cell
    silent_turntable(path, grbl)
    with pytest.raises(DeviceError, match="no Grbl banner"):
        open_rig(load_cell_file(path))
    assert ("stopScript",) in controller.calls and ("receive.disconnect",) in controller.calls


def test_a_rehearsal_cell_of_simulated_devices_checks_ok(tmp_path, capsys):
    path = tmp_path / "cell.toml"
    path.write_text(
        '[devices.camera]\ndriver = "sim"\nmodel = "l-block"\nwidth = 64\nheight = 48\nfx = 50.0\nfy = 50.0\n'
        'cx = 31.5\ncy = 23.5\n\n[devices.turntable]\ndriver = "sim"\nangle_deg = 30\n'
    )
    assert main(["devices", "check", "--config", str(path)]) == 0
    lines = capsys.readouterr().out.strip().splitlines()
    assert lines[0].split()[:3] == ["camera", "sim", "ok"] and "64x48, renders once mounted" in lines[0]
    assert lines[1] == "turntable  sim        ok      SimulatedTurntable: plate at 30.00 deg"
    assert lines[2] == "2 of 2 devices ok"


def test_a_replay_camera_is_checked_with_a_test_capture(tmp_path, capsys):
    from devices.ply import write_ply

    depths, k = rendered_views(1)
    pose = Pose.look_at((0.45, 0.0, 0.3), (0.0, 0.0, 0.06))
    frame = DepthFrame(depths[0], pose, k)
    folder = tmp_path / "views"
    folder.mkdir()
    write_ply(folder / "view_00.ply", frame.points_world)
    meta = {
        "T_world_camera": pose.to_dict(),
        "intrinsics": dict(width=80, height=60, fx=70.0, fy=72.0, cx=39.0, cy=30.5),
    }
    (folder / "view_00.json").write_text(json.dumps(meta))
    path = tmp_path / "cell.toml"
    path.write_text('[devices.camera]\ndriver = "replay"\nrecording = "views"\n')
    assert main(["devices", "check", "--config", str(path)]) == 0
    line = capsys.readouterr().out.splitlines()[0]
    assert line.split()[:3] == ["camera", "replay", "ok"]
    assert f"test capture {int((depths[0] > 0).sum())} of 4800 pixels" in line
