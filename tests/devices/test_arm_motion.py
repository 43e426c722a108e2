"""Joint paths and their timing: the straight line when free, RRT-Connect around an obstacle, ruckig's limits."""

from __future__ import annotations

import itertools
import math

import numpy as np
import pytest

from devices.arm.config import ArmConfig
from devices.arm.kinematics import ArmKinematics
from devices.arm.motion import NoPathError, plan_path, time_path
from devices.trajectory import JointTrajectory

Q_A = np.radians([0.0, -90.0, 90.0, -90.0, -90.0, 0.0])
Q_B = Q_A + np.array([1.2, 0.35, -0.5, 0.2, 0.0, 0.3])


@pytest.fixture()
def kin() -> ArmKinematics:
    return ArmKinematics(ArmConfig(planning_time=2.0), plate_radius=0.2, plate_thickness=0.02)


def block_the_middle(kin: ArmKinematics, size: float = 0.05) -> None:
    """An object box around the camera half-way along the straight line Q_A -> Q_B (plate at 0)."""
    middle = kin.camera_pose(0.5 * (Q_A + Q_B)).translation
    kin.set_object_box(middle - size, middle + size)


def assert_free(kin: ArmKinematics, waypoints: np.ndarray, angle: float = 0.0) -> None:
    resolution = math.radians(0.5)  # denser than the planner's own check
    for a, b in itertools.pairwise(waypoints):
        assert kin.world.path_collision(a, b, angle, resolution) is None


def test_a_free_straight_line_is_taken_as_is(kin: ArmKinematics) -> None:
    kin.set_object_box(None, None)
    path = plan_path(kin.world, Q_A, Q_B, 0.0)
    assert path.method == "straight"
    np.testing.assert_array_equal(path.waypoints, np.stack([Q_A, Q_B]))


def test_an_obstacle_on_the_line_makes_rrt_connect_go_around(kin: ArmKinematics) -> None:
    block_the_middle(kin)
    assert kin.world.collision(Q_A, 0.0) is None and kin.world.collision(Q_B, 0.0) is None
    blocked = kin.world.path_collision(Q_A, Q_B, 0.0, math.radians(2.0))
    assert blocked is not None and blocked.endswith(":object")
    path = plan_path(kin.world, Q_A, Q_B, 0.0, seed=3)
    assert path.method == "rrt_connect" and len(path.waypoints) >= 3
    np.testing.assert_array_equal(path.waypoints[0], Q_A)
    np.testing.assert_array_equal(path.waypoints[-1], Q_B)
    assert_free(kin, path.waypoints)
    assert all(kin.model.within_limits(q) for q in path.waypoints)


def test_no_path_in_the_time_limit_is_an_error_not_a_hang() -> None:
    kin = ArmKinematics(ArmConfig(planning_time=1e-4), plate_radius=0.2, plate_thickness=0.02)
    block_the_middle(kin, size=0.12)
    with pytest.raises(NoPathError, match=r"^no_path"):
        plan_path(kin.world, Q_A, Q_B, 0.0)


def test_a_start_in_collision_is_no_path(kin: ArmKinematics) -> None:
    camera = kin.camera_pose(Q_A).translation
    kin.set_object_box(camera - 0.03, camera + 0.03)
    with pytest.raises(NoPathError, match="start configuration is in collision"):
        plan_path(kin.world, Q_A, Q_B, 0.0)


def test_timing_respects_the_limits_and_ends_at_rest(kin: ArmKinematics) -> None:
    waypoints = np.stack([Q_A, 0.5 * (Q_A + Q_B) + [0.0, -0.3, 0.2, 0.0, 0.1, 0.0], Q_B])
    traj = time_path(kin.model, waypoints)
    assert isinstance(traj, JointTrajectory) and traj.joint_names == kin.joint_names
    np.testing.assert_allclose(traj.start, Q_A)
    np.testing.assert_allclose(traj.end, Q_B)
    np.testing.assert_allclose(traj.velocities[0], 0.0)
    np.testing.assert_allclose(traj.velocities[-1], 0.0)
    assert np.all(np.abs(traj.velocities) <= kin.model.velocity + 1e-9)
    # Stopping at the middle waypoint: the trajectory passes through it at rest.
    i = int(np.argmin(np.linalg.norm(traj.positions - waypoints[1], axis=1)))
    np.testing.assert_allclose(traj.positions[i], waypoints[1], atol=1e-9)
    # The slowest joint sets the duration: no faster than the joint that moves farthest at full speed.
    legs = np.abs(np.diff(waypoints, axis=0))
    lower_bound = float(np.sum(np.max(legs / kin.model.velocity, axis=1)))
    assert traj.duration >= lower_bound
    # Phase synchronisation: every point lies on its straight segment (the collision-checked one).
    first_leg = traj.positions[: i + 1]
    direction = (waypoints[1] - Q_A) / np.linalg.norm(waypoints[1] - Q_A)
    offsets = first_leg - Q_A
    np.testing.assert_allclose(offsets - np.outer(offsets @ direction, direction), 0.0, atol=1e-9)
    assert traj.path_length() == pytest.approx(float(np.sum(np.linalg.norm(np.diff(waypoints, axis=0), axis=1))))


def test_trajectory_truncation_stops_where_the_arm_was(kin: ArmKinematics) -> None:
    traj = time_path(kin.model, np.stack([Q_A, Q_B]))
    half = traj.truncated(0.5 * traj.duration)
    assert half.duration == pytest.approx(0.5 * traj.duration)
    np.testing.assert_allclose(half.end, traj.sample(0.5 * traj.duration))
    np.testing.assert_allclose(half.velocities[-1], 0.0)
    assert traj.truncated(0.0).duration == 0.0
