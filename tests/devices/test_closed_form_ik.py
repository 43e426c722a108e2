"""The UR5's every IK branch in closed form: each solves the pose, none is missed, and a move's target is the
shortest free one (what damped least squares from seeds approximated)."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest

from devices.arm.closed_form import SOLUTION_TOLERANCE, ClosedFormIK, closed_form
from devices.arm.config import ArmConfig
from devices.arm.kinematics import ArmKinematics
from devices.arm.model import ArmModel, example_robot_data_share, load_arm, resolve_urdf
from planner.types import Pose
from tests.helpers import orbit_view

BASE = ArmConfig().mount
TARGET = np.array([0.0, 0.0, 0.1])


@pytest.fixture(scope="module")
def arm() -> ArmModel:
    return load_arm(ArmConfig(), BASE)


@pytest.fixture(scope="module")
def solver(arm: ArmModel) -> ClosedFormIK:
    found = closed_form(arm)
    assert found is not None  # the UR5 is UR-type
    return found


def turns_apart(a: np.ndarray, b: np.ndarray) -> float:
    """The largest joint difference of two configurations, whole turns removed (radians)."""
    return float(np.max(np.abs(np.remainder(a - b + math.pi, 2 * math.pi) - math.pi)))


def test_every_branch_puts_the_camera_at_the_pose_and_the_configuration_is_among_them(
    arm: ArmModel, solver: ClosedFormIK
) -> None:
    rng = np.random.default_rng(7)
    data = arm.model.createData()
    counts = []
    for _ in range(60):
        q = rng.uniform(-math.pi, math.pi, 6)
        T = arm.camera_pose(q, data)
        found = solver.solve(T, q)
        counts.append(len(found))
        assert min(turns_apart(s, q) for s in found) < 1e-7  # the configuration the pose came from
        for s in found:
            assert np.all(np.abs(s) <= math.pi + 1e-12)
            F = arm.camera_pose(s, data)  # Pinocchio's forward kinematics, not the solver's own
            assert np.linalg.norm(F.translation - T.translation) < 1e-9
            assert np.linalg.norm(F.rotation - T.rotation) < 1e-9
        distinct = [a for i, a in enumerate(found) if all(turns_apart(a, b) > 1e-6 for b in found[:i])]
        assert len(distinct) == len(found)  # no branch twice
    assert max(counts) == 8 and min(counts) >= 2  # shoulder x wrist x elbow; some poses lose elbows to reach
    assert np.mean([c == 8 for c in counts]) > 0.5


def test_a_pose_out_of_reach_has_no_branch_and_the_wrist_singularity_keeps_the_reference_joint_6(
    arm: ArmModel, solver: ClosedFormIK
) -> None:
    far = Pose.look_at(np.array([2.5, 0.0, 0.4]), np.array([3.0, 0.0, 0.4]))
    assert solver.solve(far) == []
    q = np.array([0.3, -1.2, 1.4, -0.9, 0.0, 0.7])  # joint 5 at 0: axes 4 and 6 line up
    T = arm.camera_pose(q)
    found = solver.solve(T, q)
    assert found
    assert min(turns_apart(s, q) for s in found) < 1e-6
    for s in found:  # at the singularity within the solver's tolerance (joint 5 solved to about 1e-8 of 0)
        F = arm.camera_pose(s)
        assert np.linalg.norm(F.translation - T.translation) < SOLUTION_TOLERANCE


def test_an_arm_that_is_not_ur_type_keeps_damped_least_squares(tmp_path: Path) -> None:
    urdf, _, _ = resolve_urdf(ArmConfig())
    text = urdf.read_text()
    elbow = text.index('<joint name="elbow_joint"')
    axis = text.index('<axis xyz="0 1 0"/>', elbow)
    bent = tmp_path / "bent.urdf"  # the elbow's axis across the shoulder's: no planar arm
    bent.write_text(text[:axis] + '<axis xyz="1 0 0"/>' + text[axis + len('<axis xyz="0 1 0"/>') :])
    config = ArmConfig(urdf=str(bent), package_dirs=(str(example_robot_data_share()),))
    assert closed_form(load_arm(config, BASE)) is None
    bent_cell = ArmKinematics(config, plate_radius=0.2, plate_thickness=0.02)
    assert bent_cell.reach._closed_form is None
    T = orbit_view(TARGET, 30, 20, 0.45)  # its moves still find targets, from seeds
    target, _ = bent_cell.reach.best_target(T, bent_cell.home, 0.0)
    reference, _ = bent_cell.reach.reachability(T, bent_cell.home, 0.0)
    assert (target is None) == (reference is None)


def kinematics() -> ArmKinematics:
    k = ArmKinematics(ArmConfig(), plate_radius=0.2, plate_thickness=0.02)
    k.set_object_box(np.array([-0.08, -0.08, 0.0]), np.array([0.08, 0.08, 0.2]))
    return k


def test_a_move_target_is_never_longer_than_the_seeded_search_and_shorter_where_it_missed_a_branch() -> None:
    closed, seeded = kinematics(), kinematics()
    assert closed.reach._closed_form is not None
    seeded.reach._closed_form = None  # damped least squares from the current joints, anchor and library seeds
    rng = np.random.default_rng(3)
    views = [orbit_view(TARGET, rng.uniform(0, 80), rng.uniform(-180, 180), rng.uniform(0.35, 0.55)) for _ in range(30)]
    states = []
    for T in views[:3]:
        start, _ = closed.reach.best_target(T, closed.home, 0.0)
        assert start is not None
        states.append((start.q, start.angle))
    shorter = 0
    for q, angle in states:
        for T in views:
            a, reason_a = closed.reach.best_target(T, q, angle)
            b, reason_b = seeded.reach.best_target(T, q, angle)
            assert (a is None) == (b is None)
            if a is None or b is None:
                assert reason_a == reason_b
                continue
            assert closed.model.within_limits(a.q) and closed.violations(a.q, a.angle) is None
            assert a.move_estimate <= b.move_estimate + 2e-3  # the seeded solutions are within its tolerance
            shorter += a.move_estimate < b.move_estimate - 0.05
    assert shorter >= 3  # branches the seeds did not find (measured: 158 of 558 moves shorter, by up to 0.58 s)


def test_the_nearest_free_branch_is_the_one_checking_every_branch_gives() -> None:
    k = kinematics()
    reach = k.reach
    assert reach._closed_form is not None
    rng = np.random.default_rng(11)
    q0, a0 = k.home, 0.0
    seen_none_free = 0
    for _ in range(40):
        T = orbit_view(TARGET, rng.uniform(-20, 80), rng.uniform(-180, 180), rng.uniform(0.15, 0.55))
        for angle in reach.plate_angles(T, a0)[:3]:
            target, reason = reach._attempt(T, angle, q0, a0, first=False)
            R = np.array([[math.cos(angle), -math.sin(angle), 0], [math.sin(angle), math.cos(angle), 0], [0, 0, 1]])
            solutions, why = reach._ik(Pose.trusted(R @ T.rotation, R @ T.translation), q0, first=False)
            if not solutions:
                assert target is None and reason in ("no_ik", "joint_limit") and why == reason
                continue
            free = [
                (reach.move_estimate(q0, q, a0, angle), i)
                for i, q in enumerate(solutions)
                if reach.world.collision(q, angle) is None
            ]
            if not free:
                seen_none_free += 1
                assert target is None and reason == reach.world.collision(solutions[0], angle)
                continue
            estimate, i = min(free)
            assert target is not None and reason is None
            np.testing.assert_array_equal(target.q, solutions[i])
            assert target.move_estimate == estimate
    assert seen_none_free > 0  # views under the plate or inside the box: every branch collides
