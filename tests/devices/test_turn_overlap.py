"""The plate turns while the arm moves (``ArmConfig.turn_while_moving``) only when the arm's whole path stands clear
of the cylinder the turning object box sweeps: such a move takes the longer of the turn and the trajectory, and
the arm never meets the box at any moment of it."""

from __future__ import annotations

import math

import numpy as np
import pytest

from devices.angles import wrap_angle
from devices.arm.config import ArmConfig
from devices.builtins import make_builtin
from devices.cell import Cell
from devices.config import CameraConfig, CellConfig
from devices.faults import FaultConfig, FaultInjector, with_faults
from devices.protocols import DeviceError, UnreachableError
from devices.sim import make_sim_cell
from planner.types import BoundingBox, Pose
from tests.helpers import orbit_view

TARGET = np.array([0.0, 0.0, 0.08])
SMALL_BOX = BoundingBox(np.array([-0.1, -0.1, 0.0]), np.array([0.1, 0.1, 0.2]))
LONG_BOX = BoundingBox(np.array([-0.1, -0.1, 0.0]), np.array([0.3, 0.1, 0.2]))
"""Reaches 0.3 m from the plate's axis: its sweep takes in much of the space the arm works in."""
SPEED = math.radians(ArmConfig().turntable_speed_deg)


def view(elevation_deg: float, azimuth_deg: float, distance: float = 0.45) -> Pose:
    return orbit_view(TARGET, elevation_deg, azimuth_deg, distance)


def overlap_cell(box: BoundingBox, *, on: bool = True) -> Cell:
    cell = make_sim_cell(
        make_builtin("l-block", 0.2), CameraConfig(), CellConfig(arm=ArmConfig(turn_while_moving=on)), seed=0
    )
    cell.set_object_box(box)
    return cell


@pytest.fixture(scope="module")
def small() -> Cell:
    return overlap_cell(SMALL_BOX)


def test_an_overlapped_move_takes_the_longer_of_its_turn_and_its_trajectory(small: Cell) -> None:
    sequential = overlap_cell(SMALL_BOX, on=False)
    target = view(40, 100)
    for cell, together in ((small, True), (sequential, False)):
        motion = cell.plan_motion(target)
        assert motion.trajectory is not None and motion.retract is None
        turn = abs(wrap_angle(motion.angle - cell.angle)) / SPEED
        arm = motion.trajectory.duration
        assert turn > 0.3 and arm > 0.3  # both parts matter, so the two formulas differ
        assert motion.overlapped is together
        assert motion.to_json()["turn_overlapped"] is together
        assert motion.duration == pytest.approx(max(turn, arm) if together else turn + arm, abs=1e-9)
    cell = overlap_cell(SMALL_BOX)
    motion = cell.move_to(target)  # both devices got there
    assert motion.overlapped
    assert math.isclose(cell.angle, motion.angle)
    assert np.linalg.norm(cell.pose.translation - target.translation) < 1e-3


@pytest.mark.parametrize("box", [SMALL_BOX, LONG_BOX], ids=["small box", "long box"])
def test_an_overlapped_move_never_meets_the_turning_box(box: BoundingBox) -> None:
    cell = overlap_cell(box)
    k = cell.kinematics
    assert k is not None
    a0 = cell.angle
    overlapped = refused = 0
    targets = [view(el, float(az), distance) for el, distance in ((35, 0.45), (25, 0.35)) for az in range(0, 360, 45)]
    for target in targets:
        try:
            motion = cell.plan_motion(target)
        except UnreachableError:
            continue
        assert motion.trajectory is not None
        turn = wrap_angle(motion.angle - a0)
        if abs(turn) < 1e-6:
            continue
        if not motion.overlapped:
            refused += 1
            if motion.retract is None:  # the path itself passes through the sweep: overlapping it was refused
                assert not k.path_sweep_free(motion.trajectory.positions)
            continue
        overlapped += 1
        assert motion.retract is None  # an arm that must retract for the turn does not stand clear of it
        # run both at once as the cell does: the plate at its speed from a0, the arm along its trajectory
        for t in np.arange(0.0, motion.duration + 0.02, 0.02):
            angle = a0 + math.copysign(min(abs(turn), SPEED * t), turn)
            q = motion.trajectory.sample(float(t))
            assert k.world.collision(q, angle) is None, t
    assert overlapped >= 4
    if box is LONG_BOX:
        assert refused >= 4  # the condition decides: near the long box turning moves run one after the other


def test_move_seconds_overlap_only_when_both_ends_stand_clear() -> None:
    cell = overlap_cell(LONG_BOX)
    reach = cell.kinematics.reach  # type: ignore[union-attr]
    rng = np.random.default_rng(1)
    states = [reach.home + rng.normal(0, 0.5, reach.arm.nq) for _ in range(12)]
    angles = rng.uniform(-math.pi, math.pi, len(states))
    clear = [reach.sweep_free(q) for q in states]
    assert any(clear) and not all(clear)  # both kinds of state are compared
    m = reach.seconds_between(np.stack(states), angles, np.stack(states), angles)
    for i, (qi, ai) in enumerate(zip(states, angles, strict=True)):
        for j, (qj, aj) in enumerate(zip(states, angles, strict=True)):
            sequential = reach.move_estimate(qi, qj, ai, aj)
            turn = abs(wrap_angle(aj - ai)) / SPEED
            want = max(turn, sequential - turn) if clear[i] and clear[j] else sequential
            assert reach.move_seconds(qi, qj, ai, aj) == pytest.approx(want, abs=1e-9)
            assert m[i, j] == pytest.approx(want, abs=1e-9)
    reach.turn_while_moving = False
    sequential = [
        [reach.move_estimate(qi, qj, ai, aj) for qj, aj in zip(states, angles, strict=True)]
        for qi, ai in zip(states, angles, strict=True)
    ]
    np.testing.assert_allclose(
        reach.seconds_between(np.stack(states), angles, np.stack(states), angles), sequential, atol=1e-9
    )


def test_a_turntable_fault_during_an_overlapped_move_is_raised_and_the_retry_gets_there() -> None:
    cell = with_faults(overlap_cell(SMALL_BOX), FaultInjector(FaultConfig.from_dict({"schedule": []})))
    target = view(40, 100)
    assert cell.plan_motion(target).overlapped
    angle = cell.angle
    cell.turntable.injector.inject("turntable_error")  # type: ignore[attr-defined]
    with pytest.raises(DeviceError, match="turntable"):
        cell.move_to(target)
    assert cell.angle == angle  # the plate did not move (the arm may have: its path is clear at any plate angle)
    assert cell.kinematics.violations(cell.joint_positions(), cell.angle) is None  # type: ignore[union-attr]
    cell.move_to(target)
    assert np.linalg.norm(cell.pose.translation - target.translation) < 1e-3
