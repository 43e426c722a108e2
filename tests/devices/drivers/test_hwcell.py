"""The kinematic Cell on the drivers: plan with the UR5 model, turn the GRBL plate, run the fake UR, capture from
the RealSense recording, and place the image by forward kinematics of the joints the controller reports."""

from __future__ import annotations

import math

import numpy as np
import pytest

from devices.cellfile import load_cell_file
from devices.hwcell import hardware_cell
from devices.rig import Rig, open_rig
from tests.devices.drivers.rigfixtures import fake_hardware_cell
from tests.devices.drivers.rsfixtures import DEPTH_UNIT, rendered_views


@pytest.fixture
def fake(tmp_path):
    depths, k = rendered_views(2)
    fast = (
        "max_joint_speed_deg = 180\nmax_joint_acceleration_deg = 720\nspeed_fraction = 1.0\nacceleration_fraction = 1.0"
    )
    with fake_hardware_cell(tmp_path, depths, k, arm_speed=fast) as cell:
        yield cell, depths


def test_move_to_and_capture_on_the_drivers(fake):
    cell_file, depths = fake
    with open_rig(load_cell_file(cell_file.path)) as rig:
        cell = hardware_cell(rig)
        view = cell.initial_pose()
        motion = cell.move_to(view)
        # the plate turned on the GRBL, the arm ran the planned trajectory on the UR controller
        assert cell_file.grbl.position == pytest.approx(math.degrees(motion.angle), abs=1e-3)
        assert [c[0] for c in cell_file.controller.calls].count("moveJ") == 1
        assert motion.q is not None and np.allclose(rig.arm.joint_positions(), motion.q, atol=1e-9)
        frame = cell.capture()
        # the real image, placed where forward kinematics of the reported joints puts the camera
        assert np.max(np.abs(frame.depth - depths[0])) <= DEPTH_UNIT
        assert np.linalg.norm(frame.T_world_camera.translation - view.translation) < 1e-3
        assert np.allclose(frame.T_world_camera.rotation, view.rotation, atol=1e-3)


def test_the_arm_model_takes_the_cell_files_mount_hand_eye_and_bounds(fake):
    cell_file, _ = fake
    with open_rig(load_cell_file(cell_file.path)) as rig:
        cell = hardware_cell(rig)
        arm = cell.config.arm
        assert arm.base == (-0.85, 0.0, 0.0) and arm.base_yaw_deg == 0.0
        assert np.allclose(np.array(arm.T_flange_camera)[:3, 3], [0.0, 0.0, 0.05])
        assert arm.joint_upper_deg == rig.cell.arm.config.joint_upper_deg  # type: ignore[union-attr]


def test_a_cell_without_an_arm_is_refused(fake):
    cell_file, _ = fake
    with open_rig(load_cell_file(cell_file.path)) as rig:
        partial = Rig(rig.cell, camera=rig.camera, arm=None, turntable=rig.turntable)
        with pytest.raises(ValueError, match=r"devices.arm: a cell needs a camera, an arm and a turntable"):
            hardware_cell(partial)
