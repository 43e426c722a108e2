"""The arm model a hardware session plans with, configured from the cell file (no device opened)."""

from __future__ import annotations

import math

import numpy as np
import pytest

from devices.cellfile import CellFile, parse_cell
from devices.config import CellConfig
from devices.hwcell import arm_cell_config, arm_kinematics


def cell(arm_base: dict | None = None, **arm: object) -> CellFile:
    devices: dict = {
        "arm": {"driver": "ur", "host": "ur", **arm},
        "hand_eye": {"translation": [0.01, 0.02, 0.06], "rotation_deg": [0.0, 0.0, 90.0]},
        "arm_base": arm_base or {"translation": [-0.7, 0.1, 0.02], "rotation_deg": [0.0, 0.0, 30.0]},
    }
    return parse_cell({"devices": devices})


def test_the_arm_model_takes_hand_eye_mount_and_limits_from_the_cell_file() -> None:
    lower = [-180.0, -170.0, -160.0, -150.0, -140.0, -130.0]
    upper = [180.0, 10.0, 160.0, 150.0, 140.0, 130.0]
    cf = cell(joint_lower_deg=lower, joint_upper_deg=upper, max_joint_acceleration_deg=90.0)
    config = arm_cell_config(cf, CellConfig())
    T = np.array(config.arm.T_flange_camera)
    assert np.allclose(T[:3, 3], [0.01, 0.02, 0.06])
    assert np.allclose(T[:3, 0], [0.0, 1.0, 0.0], atol=1e-12)  # 90 deg about z: x -> y
    assert config.arm.base == pytest.approx((-0.7, 0.1, 0.02))
    assert config.arm.base_yaw_deg == pytest.approx(30.0)
    assert config.arm.joint_lower_deg == tuple(lower) and config.arm.joint_upper_deg == tuple(upper)
    assert config.arm.acceleration_limit_deg == 90.0
    config, kinematics = arm_kinematics(cf, config)
    assert np.allclose(kinematics.model.upper[1], math.radians(10.0))  # the tighter bound of the two
    assert float(np.max(kinematics.model.velocity)) <= math.radians(60.0)  # the driver's default speed limit
    assert float(np.max(kinematics.model.velocity)) > math.radians(59.0)


def test_a_tilted_arm_mount_is_refused_naming_the_field() -> None:
    cf = cell(arm_base={"translation": [-0.7, 0.0, 0.0], "rotation_deg": [10.0, 0.0, 0.0]})
    with pytest.raises(ValueError, match=r"^devices\.arm_base: tilted 10\.00 deg"):
        arm_cell_config(cf, CellConfig())


def test_only_a_hardware_cell_is_gated() -> None:
    from devices.sim import make_sim_cell

    assert make_sim_cell(None).auto_refusal() is None
