"""nbv calibrate on hardware drivers: the RealSense driver playing the target's depth images, the fake UR controller
and the fake GRBL firmware (tests/devices/drivers/rigfixtures.py). The images are rendered from where the camera
really is, ``T_table_camera @ E`` for each pose (the cell file's hand-eye is off by E), so the recovered hand-eye
must be the true one; the approved poses move the (fake) arm and plate, and --write updates the cell file."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from devices.arm.config import DEFAULT_T_FLANGE_CAMERA
from devices.calibration import pose_error
from devices.cellfile import load_cell_file
from nbv.cli import main
from planner.types import Pose
from tests.hardware_session.calibration_rig import calibration_rig

E = Pose(Rotation.from_rotvec([0.006, -0.009, 0.004]).as_matrix(), np.array([0.002, -0.003, 0.0015]))
"""The cell file's hand-eye error: the true camera is at ``T_flange_camera_file @ E``."""


@pytest.mark.slow
@pytest.mark.timeout(400)
def test_calibrate_on_the_fake_rig_moves_through_the_approved_poses_and_writes_the_cell_file(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    with calibration_rig(tmp_path, E) as (fake, poses):
        before = fake.path.read_text()
        args = ["calibrate", "--cell", str(fake.path), "--yes", "--write", "--plate-angles", "0,120,-120"]
        assert main(args) == 0
        moves = [call for call in fake.controller.calls if call[0] in ("moveJ", "servoJ")]
    out = capsys.readouterr().out
    assert f"{len(poses)} poses" in out and "residual per capture" in out and "wrote" in out
    assert len(moves) >= len(poses)  # every approved pose was driven to
    cell = load_cell_file(fake.path)
    X_true = Pose.from_matrix(np.array(DEFAULT_T_FLANGE_CAMERA)) @ E
    mm, deg = pose_error(cell.hand_eye, X_true)
    assert mm < 0.3 and deg < 0.05, (mm, deg)
    assert np.allclose(cell.arm_base.translation, [-0.85, 0.0, 0.0], atol=3e-4)  # the plate axis was where it said
    backups = list(tmp_path.glob("cell.toml.*.bak"))
    assert len(backups) == 1 and backups[0].read_text() == before
