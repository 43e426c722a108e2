"""The arm model: loading the UR5 of example-robot-data, forward kinematics, and bad configurations refused."""

from __future__ import annotations

import math
import re
from pathlib import Path

import numpy as np
import pytest

from devices.arm.config import ArmConfig
from devices.arm.kinematics import ArmKinematics
from devices.arm.model import load_arm, resolve_urdf
from devices.config import CellConfig


@pytest.fixture(scope="module")
def ur5():
    return load_arm(ArmConfig(), (-0.85, 0.0, 0.0))


def test_the_default_arm_is_the_ur5_with_its_srdf(ur5) -> None:
    urdf, srdf, dirs = resolve_urdf(ArmConfig())
    assert urdf.name == "ur5_robot.urdf" and srdf is not None and srdf.name == "ur5.srdf"
    assert "example-robot-data" in str(urdf) and dirs
    assert ur5.joint_names == (
        "shoulder_pan_joint",
        "shoulder_lift_joint",
        "elbow_joint",
        "wrist_1_joint",
        "wrist_2_joint",
        "wrist_3_joint",
    )
    assert ur5.nq == 6
    np.testing.assert_allclose(ur5.upper[2], math.pi)  # the UR5's elbow is limited to +-180 degrees
    assert np.all(ur5.velocity == pytest.approx(0.5 * np.array([3.15, 3.15, 3.15, 3.2, 3.2, 3.2])))


def test_forward_kinematics_mount_and_hand_eye(ur5) -> None:
    q = np.zeros(6)
    # The mount is baked in: the URDF root sits at the configured base.
    np.testing.assert_allclose(ur5.frame_pose("base_link", q).translation, [-0.85, 0.0, 0.0], atol=1e-12)
    # The camera is 5 cm along the flange's z axis, with the flange's orientation.
    flange = ur5.frame_pose("tool0", q)
    camera = ur5.camera_pose(q)
    np.testing.assert_allclose(camera.translation, flange.translation + 0.05 * flange.rotation[:, 2], atol=1e-12)
    np.testing.assert_allclose(camera.rotation, flange.rotation, atol=1e-12)
    # UR5 at zero: the arm stretched along +y of its base (shoulder offset), the flange 0.8173 m out in x.
    np.testing.assert_allclose(flange.translation[0], -0.85 + 0.39225 + 0.425, atol=1e-6)


def test_camera_pose_is_a_read_only_proper_pose_and_refuses_non_finite_joints(ur5) -> None:
    """``camera_pose`` skips Pose's orthonormality check (forward kinematics of finite joints is a rotation): its
    poses still are proper and read-only like every Pose's, and NaN joints are still refused by name."""
    rng = np.random.default_rng(3)
    for q in rng.uniform(-3.0, 3.0, size=(20, 6)):
        pose = ur5.camera_pose(q)
        np.testing.assert_allclose(pose.rotation.T @ pose.rotation, np.eye(3), atol=1e-12)
        assert np.linalg.det(pose.rotation) == pytest.approx(1.0, abs=1e-12)
        assert not pose.rotation.flags.writeable and not pose.translation.flags.writeable
    with pytest.raises(ValueError, match="non-finite"):
        ur5.camera_pose(np.array([0.0, np.nan, 0.0, 0.0, 0.0, 0.0]))


def test_a_turned_mount_turns_the_whole_arm() -> None:
    turned = load_arm(ArmConfig(base_yaw_deg=90.0), (0.0, -0.6, 0.0))
    straight = load_arm(ArmConfig(), (0.0, -0.6, 0.0))
    q = np.array([0.3, -1.0, 1.2, -0.5, 0.4, 0.1])
    a, b = turned.camera_pose(q).translation, straight.camera_pose(q).translation
    rel_a, rel_b = a - [0.0, -0.6, 0.0], b - [0.0, -0.6, 0.0]
    np.testing.assert_allclose(rel_a, [-rel_b[1], rel_b[0], rel_b[2]], atol=1e-9)


def test_unloadable_urdf_is_refused(tmp_path: Path) -> None:
    bad = tmp_path / "bad.urdf"
    bad.write_text("<robot name='x'><link name='a'/><joint name='j' type='revolute'>")
    with pytest.raises(ValueError, match=r"^arm\.urdf: cannot load bad\.urdf"):
        load_arm(ArmConfig(urdf=str(bad)), (-0.85, 0.0, 0.0))
    with pytest.raises(ValueError, match=r"^arm\.urdf: no such file"):
        load_arm(ArmConfig(urdf=str(tmp_path / "missing.urdf")), (-0.85, 0.0, 0.0))
    with pytest.raises(ValueError, match=r"^arm\.srdf: no such file"):
        load_arm(ArmConfig(srdf=str(tmp_path / "missing.srdf")), (-0.85, 0.0, 0.0))


def test_check_arm_fails_at_start_up_with_the_field(tmp_path: Path) -> None:
    from devices.arm import check_arm

    check_arm(ArmConfig())  # the default loads
    with pytest.raises(ValueError, match=r"^arm\.flange_frame: no frame 'flange'"):
        check_arm(ArmConfig(flange_frame="flange"))
    with pytest.raises(ValueError, match=r"^arm\.urdf: no such file"):
        check_arm(ArmConfig(urdf=str(tmp_path / "none.urdf")))


def test_missing_flange_frame_is_refused() -> None:
    with pytest.raises(ValueError, match=r"^arm\.flange_frame: no frame 'gripper' in ur5_robot\.urdf"):
        load_arm(ArmConfig(flange_frame="gripper"), (-0.85, 0.0, 0.0))


@pytest.mark.parametrize(
    ("T", "pattern"),
    [
        ([[1, 0, 0, 0], [0, 1, 0, 0], [0, 0, 2, 0], [0, 0, 0, 1]], "not a rigid transform"),
        ([[1, 0, 0, 0], [0, -1, 0, 0], [0, 0, 1, 0], [0, 0, 0, 1]], "not a rigid transform"),  # a mirror
        ([[1, 0, 0, 0], [0, 1, 0, 0], [0, 0, 1, 0], [0, 0, 1, 1]], "last row"),
        ([[1, 0, 0], [0, 1, 0], [0, 0, 1]], "4x4"),
        ([[1, 0, 0, float("nan")], [0, 1, 0, 0], [0, 0, 1, 0], [0, 0, 0, 1]], "non-finite"),
    ],
)
def test_non_rigid_hand_eye_is_refused(T, pattern: str) -> None:
    with pytest.raises(ValueError, match=rf"^arm\.T_flange_camera: .*{pattern}"):
        ArmConfig(T_flange_camera=T)


def test_inverted_joint_limits_are_refused() -> None:
    lower = (0.0, 0.0, 10.0, 0.0, 0.0, 0.0)
    upper = (90.0, 90.0, -10.0, 90.0, 90.0, 90.0)
    with pytest.raises(ValueError, match=r"^arm\.joint_lower_deg: joint elbow_joint has inverted limits"):
        load_arm(ArmConfig(joint_lower_deg=lower, joint_upper_deg=upper), (-0.85, 0.0, 0.0))
    with pytest.raises(ValueError, match=r"^arm\.joint_lower_deg: need 6 values"):
        load_arm(ArmConfig(joint_lower_deg=(0.0,)), (-0.85, 0.0, 0.0))


def test_base_inside_the_plate_is_refused() -> None:
    with pytest.raises(ValueError, match=r"^cell\.arm\.base: .* inside the plate"):
        CellConfig(arm=ArmConfig(base=(0.1, 0.0, 0.0)))
    with pytest.raises(ValueError, match=r"^arm\.base: .* inside the plate"):
        ArmKinematics(ArmConfig(base=(0.0, 0.15, 0.0)), plate_radius=0.2, plate_thickness=0.02)
    CellConfig(kinematics="reach_sphere", arm=ArmConfig(base=(0.1, 0.0, 0.0)))  # the sphere does not use it


@pytest.mark.parametrize(
    ("kwargs", "field"),
    [
        ({"urdf": ""}, "arm.urdf"),
        ({"velocity_scale": 0.0}, "arm.velocity_scale"),
        ({"velocity_scale": 1.5}, "arm.velocity_scale"),
        ({"planning_time": 0.0}, "arm.planning_time"),
        ({"planning_checks": 0}, "arm.planning_checks"),
        ({"planning_checks": 2.5}, "arm.planning_checks"),
        ({"plate_offsets_deg": ()}, "arm.plate_offsets_deg"),
        ({"table_height": 0.1}, "arm.table_height"),
        ({"ik_seeds": 0}, "arm.ik_seeds"),
        ({"camera_size": (0.1, 0.1)}, "arm.camera_size"),
        ({"base": (0.0, float("inf"), 0.0)}, "arm.base"),
        ({"flange_frame": 3}, "arm.flange_frame"),
    ],
)
def test_bad_arm_settings_name_the_field(kwargs, field: str) -> None:
    with pytest.raises(ValueError, match="^" + re.escape(field) + ":"):
        ArmConfig(**kwargs)


def test_arm_config_from_a_nested_dict() -> None:
    from devices.config import DeviceConfig
    from planner.config import from_dict

    cfg = from_dict(
        DeviceConfig, {"cell": {"kinematics": "urdf", "arm": {"base": [-0.8, 0.1, 0.0], "velocity_scale": 1}}}
    )
    assert cfg.cell.arm.base == (-0.8, 0.1, 0.0) and cfg.cell.arm.velocity_scale == 1.0
    with pytest.raises(ValueError, match=r"^cell\.kinematics:"):
        from_dict(DeviceConfig, {"cell": {"kinematics": "delta"}})
