"""IK, joint limits, collisions and the plate angle: which views the UR5 reaches, and why not."""

from __future__ import annotations

import math

import numpy as np
import pytest

from devices.arm.config import ArmConfig
from devices.arm.ik import fit_limits
from devices.arm.kinematics import ArmKinematics
from devices.arm.reach import rz_matrix
from planner.types import Pose
from tests.helpers import orbit_view

TARGET = np.array([0.0, 0.0, 0.1])


def view(elevation_deg: float, azimuth_deg: float, distance: float = 0.45) -> Pose:
    return orbit_view(TARGET, elevation_deg, azimuth_deg, distance)


@pytest.fixture(scope="module")
def kin() -> ArmKinematics:
    k = ArmKinematics(ArmConfig(), plate_radius=0.2, plate_thickness=0.02)
    k.set_object_box(np.array([-0.08, -0.08, 0.0]), np.array([0.08, 0.08, 0.2]))
    return k


def assert_valid_target(kin: ArmKinematics, T_table_camera: Pose, target) -> None:
    """The target's joints are inside the limits, collision-free, and put the camera at the view."""
    assert kin.model.within_limits(target.q)
    assert kin.violations(target.q, target.angle) is None
    T_base_camera = kin.camera_pose(target.q)
    T_table = Pose(rz_matrix(-target.angle), np.zeros(3)) @ T_base_camera
    assert np.linalg.norm(T_table.translation - T_table_camera.translation) < 1e-3
    cos = (np.trace(T_table.rotation.T @ T_table_camera.rotation) - 1) / 2
    assert math.degrees(math.acos(min(1.0, cos))) < 0.1


@pytest.mark.parametrize(("elevation", "azimuth"), [(10, 0), (30, 90), (45, 200), (60, -45), (70, 135)])
def test_views_on_the_hemisphere_are_reached_exactly(kin: ArmKinematics, elevation: float, azimuth: float) -> None:
    T = view(elevation, azimuth)
    target, reason = kin.reach.reachability(T, kin.home, 0.0)
    assert reason is None and target is not None
    assert_valid_target(kin, T, target)
    best, reason = kin.reach.best_target(T, kin.home, 0.0)
    assert reason is None and best is not None
    assert_valid_target(kin, T, best)
    assert best.move_estimate <= target.move_estimate + 1e-9  # the shortest move among every plate angle


def test_the_plate_angle_puts_the_view_at_an_offset_from_the_arm(kin: ArmKinematics) -> None:
    T = view(30, 123)
    angles = kin.reach.plate_angles(T, 0.0)
    for angle, offset in zip(angles, ArmConfig().plate_offsets_deg, strict=True):
        p = rz_matrix(angle) @ T.translation
        azimuth = math.degrees(math.atan2(p[1], p[0]))
        expected = math.degrees(kin.reach.arm_azimuth) + offset
        assert math.isclose(math.remainder(azimuth - expected, 360.0), 0.0, abs_tol=1e-6)


def test_views_far_out_of_reach_are_no_ik(kin: ArmKinematics) -> None:
    far = Pose.look_at([2.5, 0.0, 0.4], TARGET)
    ok, reason = kin.reachability(far, kin.home, 0.0)
    assert not ok and reason == "no_ik"
    top = view(85, 0.0, distance=0.5)  # straight above the object, beyond the UR5 from beside the plate
    ok, reason = kin.reachability(top, kin.home, 0.0)
    assert not ok and reason == "no_ik"


def test_a_view_inside_the_object_box_is_a_collision_with_the_object(kin: ArmKinematics) -> None:
    inside = Pose.look_at([0.05, 0.0, 0.12], TARGET + np.array([0.0, 0.0, -0.05]))
    ok, reason = kin.reachability(inside, kin.home, 0.0)
    assert not ok and reason is not None
    assert reason.startswith("collision:") and reason.endswith(":object"), reason


def test_a_view_under_the_plate_top_collides_with_the_plate_or_the_table(kin: ArmKinematics) -> None:
    low = Pose.look_at([0.3, 0.0, -0.03], [0.0, 0.0, -0.03])
    ok, reason = kin.reachability(low, kin.home, 0.0)
    assert not ok and reason is not None
    assert reason.startswith("collision:") and reason.split(":")[2] in ("plate", "table"), reason


def test_narrow_joint_limits_give_joint_limit() -> None:
    home = (0.0, -90.0, 90.0, -90.0, -90.0, 0.0)
    narrow = ArmKinematics(
        ArmConfig(
            joint_lower_deg=tuple(h - 15.0 for h in home),
            joint_upper_deg=tuple(h + 15.0 for h in home),
            plate_offsets_deg=(0.0,),
        ),
        plate_radius=0.2,
        plate_thickness=0.02,
    )
    T = view(20, 180)  # reachable by the full UR5, but not with every joint within 15 degrees of home
    ok, reason = narrow.reachability(T, narrow.home, 0.0)
    assert not ok and reason == "joint_limit"


def test_fit_limits_wraps_whole_turns_towards_the_reference() -> None:
    lower, upper = np.full(2, -2 * math.pi), np.full(2, 2 * math.pi)
    q = np.array([3.0, -3.0])
    np.testing.assert_allclose(
        fit_limits(q, np.array([-3.0, 3.0]), lower, upper), [3.0 - 2 * math.pi, -3.0 + 2 * math.pi]
    )
    np.testing.assert_allclose(fit_limits(q, np.zeros(2), lower, upper), q)
    assert fit_limits(np.array([3.0, 0.0]), np.zeros(2), np.array([-1.0, -1.0]), np.array([1.0, 1.0])) is None


def test_cells_of_one_arm_and_plate_share_one_seed_library_equal_to_a_fresh_one() -> None:
    from devices.arm import reach

    a = ArmKinematics(ArmConfig(), plate_radius=0.2, plate_thickness=0.02)
    b = ArmKinematics(ArmConfig(), plate_radius=0.2, plate_thickness=0.02)
    assert b.reach._library is a.reach._library  # computed once per process
    wider = ArmKinematics(ArmConfig(), plate_radius=0.3, plate_thickness=0.02)
    assert wider.reach._library is not a.reach._library  # another plate, other collisions
    reach._LIBRARIES.clear()
    fresh = ArmKinematics(ArmConfig(), plate_radius=0.2, plate_thickness=0.02)
    assert fresh.reach._library is not a.reach._library
    assert len(fresh.reach._library) == len(a.reach._library) > 0
    assert all(np.array_equal(p, q) for p, q in zip(fresh.reach._library, a.reach._library, strict=True))
    assert fresh.reach.reach == a.reach.reach
    assert all(wider.world.collision(q, 0.0) is None for q in wider.reach._library)  # checked in its own world


@pytest.mark.parametrize("turn_while_moving", [False, True])
def test_best_target_is_the_shortest_of_every_angle_while_skipping_the_turns_that_cannot_win(
    turn_while_moving: bool,
) -> None:
    k = ArmKinematics(ArmConfig(), plate_radius=0.2, plate_thickness=0.02)
    k.set_object_box(np.array([-0.08, -0.08, 0.0]), np.array([0.08, 0.08, 0.2]))
    reach = k.reach
    reach.turn_while_moving = turn_while_moving
    speed = math.radians(ArmConfig().turntable_speed_deg)
    starts = [(k.home, 0.0)]
    for elevation, azimuth in [(30, 40), (55, -120)]:
        start, _ = reach.reachability(view(elevation, azimuth), k.home, 0.0)
        assert start is not None
        starts.append((start.q, start.angle))
    tried: list[float] = []
    attempt = reach._attempt

    def counted(T: Pose, angle: float, q: np.ndarray, a: float, *, first: bool) -> tuple:
        tried.append(angle)
        return attempt(T, angle, q, a, first=first)

    reach._attempt = counted  # type: ignore[method-assign]
    skipped = 0
    for q, a in starts:
        for elevation, azimuth in [(15, 0), (35, 75), (50, 160), (65, -100), (25, -30), (45, 120)]:
            T = view(elevation, azimuth)
            angles = reach.plate_angles(T, a)
            every = []  # the oracle: every plate angle's shortest free branch, the earlier angle among equals
            for order, angle in enumerate(angles):
                target, _ = attempt(T, angle, q, a, first=False)
                if target is not None:
                    seconds = reach.move_seconds(q, target.q, a, angle) if turn_while_moving else target.move_estimate
                    every.append((seconds, order, target))
            tried.clear()
            best, reason = reach.best_target(T, q, a)
            if not every:
                assert best is None and reason is not None
                continue
            seconds, _, target = min(every, key=lambda e: e[:2])
            assert best is not None and reason is None
            assert (best.angle, best.move_estimate) == (target.angle, seconds)
            np.testing.assert_array_equal(best.q, target.q)
            for angle in set(angles) - set(tried):  # an angle left out turns for longer than the best move takes
                assert abs(math.remainder(angle - a, 2 * math.pi)) / speed > seconds - 1e-12
            skipped += len(angles) - len(tried)
    assert skipped > 0  # the nearest turns first: some angles never needed their IK
