"""The plate's turn is part of reachability: the UR5 cell retracts the arm before a turn that would sweep the
object's box into it, and never calls a view reachable that the move then refuses for the turn."""

from __future__ import annotations

import math

import numpy as np
import pytest

from devices.angles import wrap_angle
from devices.builtins import make_builtin
from devices.cell import Cell
from devices.config import CameraConfig, CellConfig
from devices.protocols import UnreachableError
from devices.sim import make_sim_cell
from planner.types import BoundingBox, Pose
from tests.helpers import orbit_view

TARGET = np.array([0.0, 0.0, 0.05])


def view(azimuth_deg: float, elevation_deg: float, distance: float) -> Pose:
    return orbit_view(TARGET, elevation_deg, azimuth_deg, distance)


@pytest.fixture(scope="module")
def close_cell() -> Cell:
    """The arm low and close to the plate on the -x side; then a box that, turned half a turn, meets it."""
    cell = make_sim_cell(make_builtin("l-block"), CameraConfig(), CellConfig(), seed=0)
    cell.move_to(view(180.0, 10.0, 0.3))
    cell.set_object_box(BoundingBox(np.array([-0.1, -0.1, 0.0]), np.array([0.3, 0.1, 0.2])))
    return cell


def test_a_sweeping_turn_retracts_the_arm_first(close_cell: Cell) -> None:
    k = close_cell.kinematics
    assert k is not None
    q, angle = close_cell.arm.joint_positions(), close_cell.angle
    assert k.turn_collision(q, angle, math.pi) is not None  # standing still, the arm would be hit
    assert k.turn_collision(k.home, angle, math.pi) is None  # retracted, it is clear
    retracted = 0
    for az in range(0, 360, 30):
        for el in (20.0, 40.0, 60.0):
            pose = view(float(az), el, 0.5)
            ok, _ = close_cell.reachability(pose)
            try:
                motion = close_cell.plan_motion(pose)
            except UnreachableError as exc:
                assert not ok or "plate turns" not in str(exc)
                continue
            standing_hit = k.turn_collision(q, angle, wrap_angle(motion.angle - angle))
            assert (standing_hit is not None) == (motion.retract is not None), (az, el)
            if motion.retract is not None:
                retracted += 1
                assert np.allclose(motion.retract.positions[0], q, atol=1e-3)
                assert np.allclose(motion.retract.positions[-1], k.home, atol=1e-6)
                assert motion.to_json()["retracted"] is True
    assert retracted >= 1


def test_reachability_and_the_move_agree_on_turns() -> None:
    """The issue's box (B grown to the plate by noise): every view reachability accepts is planned without a
    turn refusal; every view it refuses for the turn, the move refuses too."""
    cell = make_sim_cell(make_builtin("l-block"), CameraConfig(), CellConfig(), seed=0)
    cell.move_to(view(180.0, 10.0, 0.3))
    cell.set_object_box(BoundingBox(np.array([-0.19, -0.2, 0.0]), np.array([0.76, 0.22, 0.22])))
    checked = 0
    for az in range(0, 360, 45):
        for el in (15.0, 45.0):
            pose = view(float(az), el, 0.45)
            ok, why = cell.reachability(pose)
            try:
                cell.plan_motion(pose)
                refusal = None
            except UnreachableError as exc:
                refusal = str(exc)
            if ok:
                assert refusal is None or "plate turns" not in refusal, (az, el, refusal)
                checked += 1
            elif why is not None and why.startswith("turn:"):
                assert refusal is not None and "plate turns" in refusal
    assert checked > 0


def test_a_retracted_move_ends_at_the_view(close_cell: Cell) -> None:
    poses = [view(float(az), el, 0.5) for az in range(0, 360, 30) for el in (20.0, 40.0, 60.0)]
    for pose in poses:
        try:
            planned = close_cell.plan_motion(pose)
        except UnreachableError:
            continue
        if planned.retract is not None:
            break
    else:
        pytest.fail("no view needs a retract")
    motion = close_cell.move_to(pose)
    assert motion.retract is not None
    assert np.allclose(close_cell.pose.translation, pose.translation, atol=1e-4)
    assert close_cell.kinematics is not None
    assert close_cell.kinematics.violations(close_cell.arm.joint_positions(), close_cell.angle) is None
    assert motion.duration > motion.retract.duration > 0


def test_turn_answers_match_a_walk_of_the_whole_grid() -> None:
    """turn_collision keeps the grid's first collision per (configuration, angle, direction) and walks the grid only
    as far as asked: every answer, asked in any order, short turns after long ones and back, is the first collision
    of the turn's own grid (k / TURN_CHECKS_PER_RADIAN, k = 0 .. n, then the end), checked afresh here."""
    from devices.arm.kinematics import TURN_CHECKS_PER_RADIAN

    close_cell = make_sim_cell(make_builtin("l-block"), CameraConfig(), CellConfig(), seed=0)
    close_cell.move_to(view(180.0, 10.0, 0.3))
    box = BoundingBox(np.array([-0.1, -0.1, 0.0]), np.array([0.3, 0.1, 0.2]))
    close_cell.set_object_box(box)
    k = close_cell.kinematics
    assert k is not None
    world = k.world

    def reference(q: np.ndarray, angle: float, turn: float) -> str | None:
        step = 1.0 / TURN_CHECKS_PER_RADIAN
        offsets = [math.copysign(i * step, turn) for i in range(math.floor(abs(turn) / step) + 1)] + [turn]
        for offset in offsets:
            hit = world.collision(q, angle + offset)
            if hit is not None:
                return hit
        return None

    q, angle = close_cell.arm.joint_positions(), close_cell.angle
    turns = [math.pi, 0.3, -0.2, 2.9, -math.pi, 0.0, -0.0, 1.234, -2.5, 0.05, math.pi - 1e-9, -1.7]
    rng = np.random.default_rng(0)
    hits = 0
    for turn in [*turns, *rng.uniform(-math.pi, math.pi, 40)]:
        for config in (q, k.home):
            expected = reference(config, angle, float(turn))
            assert k.turn_collision(config, angle, float(turn)) == expected, (turn, expected)
            hits += expected is not None
    assert hits >= 10  # the close arm is hit by many of these turns: the walks' collisions are exercised
    # a new box forgets the walks (the collisions change with it)
    before = k.turn_collision(q, angle, math.pi)
    close_cell.set_object_box(BoundingBox(np.array([-0.02, -0.02, 0.0]), np.array([0.02, 0.02, 0.02])))
    assert before is not None
    assert k.turn_collision(q, angle, math.pi) == reference(q, angle, math.pi) is None
    close_cell.set_object_box(box)
    assert k.turn_collision(q, angle, math.pi) == before


def test_turning_collision_is_collision_at_every_angle() -> None:
    """CollisionWorld.turning_collision checks the pairs the plate does not move once per configuration and the
    box's pairs per angle: the same answer (and reason: the first colliding pair in the pairs' order) as a full
    collision check, for configurations free, hitting the box, the plate or the table, or themselves, asked in any
    order and interleaved with other configurations' checks."""
    cell = make_sim_cell(make_builtin("l-block"), CameraConfig(), CellConfig(), seed=0)
    cell.move_to(view(180.0, 10.0, 0.3))  # low and close: turned half a turn, the box meets the arm
    cell.set_object_box(BoundingBox(np.array([-0.1, -0.1, 0.0]), np.array([0.3, 0.1, 0.2])))
    k = cell.kinematics
    assert k is not None
    world, model = k.world, k.model
    rng = np.random.default_rng(5)
    configs = [k.home, cell.arm.joint_positions(), *rng.uniform(model.lower, model.upper, (60, model.nq))]
    angles = [0.0, 0.4, -1.3, math.pi, 2.2, *rng.uniform(-math.pi, math.pi, 6)]
    reasons: set[str] = set()
    for _ in range(2):
        for q in configs:
            for angle in angles:
                expected = world.collision(q, angle)
                other = configs[int(rng.integers(len(configs)))]
                world.collision(other, float(rng.uniform(-3, 3)))  # moves the geometries elsewhere meanwhile
                assert world.turning_collision(q, angle) == expected, (q, angle)
                assert world.turning_collision(q, angle) == expected
                reasons.add("free" if expected is None else expected.split(":")[2])
        rng.shuffle(configs)
    assert {"free", "object"} <= reasons and len(reasons) >= 4, reasons  # the box, the fixed obstacles, free
