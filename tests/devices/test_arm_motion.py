"""Joint paths and their timing: the straight line when free, RRT-Connect around an obstacle (reproducible, within
a collision-check budget, on any machine load), ruckig's limits."""

from __future__ import annotations

import dataclasses
import itertools
import math
import time

import numpy as np
import pytest

from devices.arm import motion
from devices.arm.config import ArmConfig
from devices.arm.kinematics import ArmKinematics
from devices.arm.motion import NoPathError, plan_path, time_path
from devices.trajectory import JointTrajectory

Q_A = np.radians([0.0, -90.0, 90.0, -90.0, -90.0, 0.0])
Q_B = Q_A + np.array([1.2, 0.35, -0.5, 0.2, 0.0, 0.3])


@pytest.fixture()
def kin() -> ArmKinematics:
    return ArmKinematics(ArmConfig(), plate_radius=0.2, plate_thickness=0.02)


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


def assert_identical(a: motion.PathPlan, b: motion.PathPlan) -> None:
    assert a.method == b.method == "rrt_connect" and a.checks == b.checks
    np.testing.assert_array_equal(a.waypoints, b.waypoints)  # bit for bit


def test_rrt_connect_gives_the_same_path_every_time(kin: ArmKinematics) -> None:
    block_the_middle(kin, size=0.08)
    first = plan_path(kin.world, Q_A, Q_B, 0.0)
    np.random.seed(7)  # the process's other random state does not enter
    np.random.uniform(size=100)
    other = plan_path(kin.world, Q_A, Q_B, 0.0, seed=2)  # nor does the planner's history
    again = plan_path(kin.world, Q_A, Q_B, 0.0)
    assert_identical(first, again)
    assert time_path(kin.model, first.waypoints).duration == time_path(kin.model, again.waypoints).duration
    assert not np.array_equal(first.waypoints, other.waypoints)  # the seed (and the inputs) choose the samples
    # A fresh cell (a new process builds one) plans the same path.
    fresh = ArmKinematics(ArmConfig(), plate_radius=0.2, plate_thickness=0.02)
    block_the_middle(fresh, size=0.08)
    assert_identical(first, plan_path(fresh.world, Q_A, Q_B, 0.0))


def test_the_shortcut_leaves_no_waypoint_that_could_be_skipped(kin: ArmKinematics) -> None:
    block_the_middle(kin, size=0.12)
    resolution = math.radians(kin.config.path_resolution_deg)
    for seed in range(3):
        waypoints = plan_path(kin.world, Q_A, Q_B, 0.0, seed=seed).waypoints
        assert_free(kin, waypoints)
        for a, b in zip(waypoints[:-2], waypoints[2:], strict=True):  # greedy: the next but one is not in sight
            assert kin.world.path_collision(a, b, 0.0, resolution) is not None


def slow_checks(kin: ArmKinematics, monkeypatch: pytest.MonkeyPatch, delay: float) -> list[int]:
    """Every collision check of ``kin`` sleeps ``delay`` seconds (a loaded machine); returns the call counter."""
    calls = [0]
    collision = kin.world.collision

    def slow(q: np.ndarray, angle: float) -> str | None:
        calls[0] += 1
        time.sleep(delay)
        return collision(q, angle)

    monkeypatch.setattr(kin.world, "collision", slow)
    return calls


def test_a_slow_machine_plans_the_same_path(kin: ArmKinematics, monkeypatch: pytest.MonkeyPatch) -> None:
    block_the_middle(kin, size=0.08)
    fast = plan_path(kin.world, Q_A, Q_B, 0.0)
    slow_checks(kin, monkeypatch, 2e-4)
    slow = plan_path(kin.world, Q_A, Q_B, 0.0)
    assert_identical(fast, slow)
    assert slow.seconds > fast.checks * 2e-4  # it did run slowly
    # Only the hang guard looks at the clock: far too short for this machine, it refuses the move.
    guard = dataclasses.replace(kin.config, planning_time=fast.checks * 2e-4 / 4)
    monkeypatch.setattr(kin.world, "arm", dataclasses.replace(kin.world.arm, config=guard))
    with pytest.raises(NoPathError, match=r"^no_path: .* within its wall-clock guard"):
        plan_path(kin.world, Q_A, Q_B, 0.0)


def test_an_impossible_move_is_no_path_after_the_check_budget(monkeypatch: pytest.MonkeyPatch) -> None:
    # Only the base joint may move (the others held within a degree), and the object blocks its only way.
    q_to = Q_A + np.array([1.2, 0.0, 0.0, 0.0, 0.0, 0.0])
    lower, upper = np.degrees(np.minimum(Q_A, q_to)) - 1.0, np.degrees(np.maximum(Q_A, q_to)) + 1.0
    config = ArmConfig(planning_checks=1000, joint_lower_deg=tuple(lower), joint_upper_deg=tuple(upper))
    kin = ArmKinematics(config, plate_radius=0.2, plate_thickness=0.02)
    middle = kin.camera_pose(0.5 * (Q_A + q_to)).translation
    kin.set_object_box(middle - 0.05, middle + 0.05)
    calls = slow_checks(kin, monkeypatch, 0.0)
    with pytest.raises(NoPathError, match=r"^no_path: RRT-Connect found no collision-free path within 1000 collision"):
        plan_path(kin.world, Q_A, q_to, 0.0)
    straight = math.ceil(1.2 / math.radians(kin.config.path_resolution_deg)) + 1
    assert 1000 < calls[0] <= 2 + straight + 1000  # start, goal, the straight line (up to its hit), the budget


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
