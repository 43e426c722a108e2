"""The reachability cache (per view, plate angle and object box) and the swept-box turn test give the same answers
as computing every attempt and every turn afresh, so a plan with them makes the same choices as without."""

from __future__ import annotations

import math

import numpy as np
import pytest

from devices.arm.config import ArmConfig
from devices.arm.kinematics import ArmKinematics
from planner.candidates import propose_candidates
from planner.config import PlannerConfig
from planner.types import BoundingBox, Pose

BOX = BoundingBox(np.array([-0.12, -0.09, 0.0]), np.array([0.1, 0.09, 0.21]))
OTHER_BOX = BoundingBox(np.array([-0.2, -0.1, 0.0]), np.array([0.3, 0.12, 0.22]))


def hemisphere(box: BoundingBox, step: int = 5) -> list[Pose]:
    """Every ``step``-th candidate of the paper's hemisphere about ``box``."""
    cfg = PlannerConfig()
    candidates, _, _ = propose_candidates(box, cfg.candidates, cfg.partitions)
    return [c.T_world_camera for c in candidates[::step]]


@pytest.fixture(scope="module")
def pair() -> tuple[ArmKinematics, ArmKinematics]:
    """(cached, reference): two UR5 models, the second with the attempt cache and the sweep test off."""
    cached = ArmKinematics(ArmConfig(), plate_radius=0.2, plate_thickness=0.02)
    reference = ArmKinematics(ArmConfig(), plate_radius=0.2, plate_thickness=0.02)
    reference.reach.use_attempt_cache = False
    reference.use_sweep_test = False
    reference.reach._anchors = {}  # its own IK anchors too, solved afresh (the cells of one arm share theirs)
    return cached, reference


def answers(kin: ArmKinematics, poses: list[Pose], q: np.ndarray, angle: float) -> list[tuple[bool, str | None]]:
    return [kin.reachability(T, q, angle) for T in poses]


def test_cached_reachability_equals_the_reference_cold_warm_and_after_a_box_change(pair) -> None:
    cached, reference = pair
    poses = hemisphere(BOX)
    q0 = cached.home
    for box in (BOX, OTHER_BOX, BOX):  # cold, a new box (new keys), the first box again (warm)
        for kin in pair:
            kin.set_object_box(box.lower, box.upper)
        for q, angle in ((q0, 0.0), (q0 + 0.3, 1.2)):  # the verdicts of two arm states
            got, want = answers(cached, poses, q, angle), answers(reference, poses, q, angle)
            assert got == want
        assert 0 < sum(ok for ok, _ in want) < len(want)  # both kinds of answer are compared
    assert len(cached.reach._attempts) > 0


def test_cached_targets_are_the_targets_computed_afresh(pair) -> None:
    cached, reference = pair
    for kin in pair:
        kin.set_object_box(BOX.lower, BOX.upper)
    for T in hemisphere(BOX, step=40):
        for _ in range(2):  # the second ask is served by the cache
            a, ra = cached.reach.reachability(T, cached.home, 0.4)
            b, rb = reference.reach.reachability(T, reference.home, 0.4)
            assert ra == rb
            if a is not None and b is not None:
                assert a.angle == b.angle
                np.testing.assert_array_equal(a.q, b.q)
                assert a.move_estimate == pytest.approx(b.move_estimate, abs=1e-12)


def test_reachable_angle_is_the_angle_of_reachability_cached_or_not(pair) -> None:
    """``reachable_angle`` (the planner's question: no move estimate) gives the plate angle and reason
    ``reachability`` gives, from the cache and afresh, in the same order of questions (the offset that served the
    previous one first)."""
    for kin in pair:
        kin.set_object_box(OTHER_BOX.lower, OTHER_BOX.upper)
    found = 0
    for T in hemisphere(OTHER_BOX, step=7):
        for kin in pair:
            last = kin.reach._last_offset
            angle, reason = kin.reach.reachable_angle(T, kin.home, 0.7)
            kin.reach._last_offset = last  # the same question again, from the same state
            target, why = kin.reach.reachability(T, kin.home, 0.7)
            assert reason == why
            assert (angle is None) == (target is None)
            if target is not None:
                assert angle == target.angle
                found += 1
    assert 0 < found < 2 * len(hemisphere(OTHER_BOX, step=7))  # both kinds of answer


def test_sweep_test_agrees_with_the_turn_grid(pair) -> None:
    cached, reference = pair
    low_box = BoundingBox(np.array([-0.1, -0.1, 0.0]), np.array([0.35, 0.1, 0.25]))
    for kin in pair:
        kin.set_object_box(low_box.lower, low_box.upper)
    rng = np.random.default_rng(3)
    states = [cached.home, *(cached.home + rng.normal(0, 0.6, cached.model.nq) for _ in range(12))]
    blocked = 0
    for q in states:
        for turn in (-2.5, -1.0, 0.4, 1.7, math.pi):
            got, want = cached.turn_collision(q, 0.3, turn), reference.turn_collision(q, 0.3, turn)
            assert got == want
            blocked += want is not None
    assert blocked > 0  # some turns do sweep the box into the arm: the fallback to the grid is exercised


def test_seconds_between_is_move_estimate_for_every_pair(pair) -> None:
    reach = pair[0].reach
    rng = np.random.default_rng(0)
    q = reach.home + rng.normal(0, 0.8, (5, reach.arm.nq))
    angles = rng.uniform(-math.pi, math.pi, 5)
    m = reach.seconds_between(q, angles, q, angles)
    for i in range(5):
        for j in range(5):
            assert m[i, j] == pytest.approx(reach.move_estimate(q[i], q[j], angles[i], angles[j]), rel=1e-12)
    assert np.all(np.diag(m) == 0) and np.all(m[~np.eye(5, dtype=bool)] > 0)


def test_the_cells_of_one_arm_share_their_ik_anchors_and_find_the_same_targets() -> None:
    """A new cell of an arm finds the IK anchors the earlier cells of that arm solved (one dict per arm, plate and
    home in the process) and reaches the same verdicts and targets (reachability and the move's best target) as a
    cell that solves every anchor itself; another plate has anchors of its own."""
    first = ArmKinematics(ArmConfig(), plate_radius=0.2, plate_thickness=0.02)
    poses = hemisphere(BOX, step=7)
    first.set_object_box(BOX.lower, BOX.upper)
    q0 = first.home
    want = [first.reachability(T, q0, 0.0) for T in poses]
    solved = len(first.reach._anchors)  # with the anchors of the cells built before in this process
    second = ArmKinematics(ArmConfig(), plate_radius=0.2, plate_thickness=0.02)
    alone = ArmKinematics(ArmConfig(), plate_radius=0.2, plate_thickness=0.02)
    alone.reach._anchors = {}
    assert second.reach._anchors is first.reach._anchors
    for kin in (second, alone):
        kin.set_object_box(BOX.lower, BOX.upper)
        assert [kin.reachability(T, q0, 0.0) for T in poses] == want
    assert len(first.reach._anchors) == solved  # the second cell had nothing new to solve
    shared = first.reach._anchors
    assert alone.reach._anchors.keys() <= shared.keys() and len(alone.reach._anchors) > 10
    for key, anchor in alone.reach._anchors.items():  # and what the lone cell solved is what is shared
        assert (anchor is None and shared[key] is None) or np.array_equal(anchor, shared[key])
    for T in poses[::3]:
        a, _ = second.reach.best_target(T, q0 + 0.2, 0.3)
        b, _ = alone.reach.best_target(T, q0 + 0.2, 0.3)
        assert (a is None) == (b is None)
        if a is not None and b is not None:
            assert a.angle == b.angle and np.array_equal(a.q, b.q) and a.move_estimate == b.move_estimate
    other_plate = ArmKinematics(ArmConfig(), plate_radius=0.2, plate_thickness=0.03)
    assert other_plate.reach._anchors is not first.reach._anchors
