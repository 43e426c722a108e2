"""A move planned for the next one (``ArmReach.best_target(then=...)``, the tour's ring): the
target minimises this move plus the quickest move on to one of the next views, over every plate angle and IK branch
of both; without a reachable next view it is the plain shortest move."""

from __future__ import annotations

import math

import numpy as np
import pytest

from devices.arm.config import ArmConfig
from devices.arm.ik import fit_limits, fit_limits_toward
from devices.arm.kinematics import ArmKinematics
from planner.types import Pose
from tests.devices.test_arm_reach import assert_valid_target
from tests.helpers import orbit_view

TARGET = np.array([0.0, 0.0, 0.1])


def view(elevation_deg: float, azimuth_deg: float) -> Pose:
    return orbit_view(TARGET, elevation_deg, azimuth_deg, 0.45)


@pytest.fixture(scope="module")
def kin() -> ArmKinematics:
    k = ArmKinematics(ArmConfig(), plate_radius=0.2, plate_thickness=0.02)
    k.set_object_box(np.array([-0.08, -0.08, 0.0]), np.array([0.08, 0.08, 0.2]))
    return k


def onward(kin: ArmKinematics, q: np.ndarray, angle: float, views: list[Pose]) -> float:
    """The quickest move the cell would make from (q, angle) to one of ``views``."""
    moves = [kin.reach.best_target(v, q, angle)[0] for v in views]
    return min(m.move_estimate for m in moves if m is not None)


def test_the_move_is_chosen_for_this_move_and_the_next_together(kin: ArmKinematics) -> None:
    """A low view 150 deg round, then one of two views 120-130 deg further (a ring's two sides): the plain shortest
    move (1.96 s) leaves the arm 2.67 s from the next; the look-ahead takes a longer first move (2.34 s) from which
    the next is 2.10 s, 0.19 s less in all. The sum is the least over every plate angle and free branch of the view
    (each followed by the cell's own quickest next move), and the target puts the camera at the view."""
    reach, home = kin.reach, kin.reach.home
    here, nexts = view(10, 150), [view(10, 270), view(20, 280)]
    plain, _ = reach.best_target(here, home, 0.0)
    ahead, reason = reach.best_target(here, home, 0.0, then=nexts)
    assert plain is not None and ahead is not None and reason is None
    assert_valid_target(kin, here, ahead)
    plain_sum = plain.move_estimate + onward(kin, plain.q, plain.angle, nexts)
    ahead_sum = ahead.move_estimate + onward(kin, ahead.q, ahead.angle, nexts)
    assert ahead.move_estimate > plain.move_estimate + 0.2  # a longer first move ...
    assert ahead_sum < plain_sum - 0.1  # ... for a shorter pair
    assert ahead.move_estimate == pytest.approx(reach.move_seconds(home, ahead.q, 0.0, ahead.angle))
    every = [  # every plate angle and free branch of the view, each with the cell's quickest next move
        reach.move_seconds(home, q, 0.0, angle) + onward(kin, q, angle, nexts)
        for angle in reach.plate_angles(here, 0.0)
        for q in reach._free_branches(here, angle, home)[0]  # the free branches the move chooses among
    ]
    assert len(every) >= 4
    assert ahead_sum == pytest.approx(min(every), abs=1e-9)


def test_without_a_reachable_next_view_the_move_is_the_shortest(kin: ArmKinematics) -> None:
    """Next views the arm reaches at no plate angle (2 m out) leave the choice to the move alone."""
    reach, home = kin.reach, kin.reach.home
    here = view(10, 150)
    far = orbit_view(TARGET, 10, 270, 2.0)
    assert reach.best_target(far, home, 0.0)[0] is None
    plain, _ = reach.best_target(here, home, 0.0)
    ahead, _ = reach.best_target(here, home, 0.0, then=[far])
    assert plain is not None and ahead is not None
    assert ahead.angle == plain.angle and np.array_equal(ahead.q, plain.q)
    assert ahead.move_estimate == plain.move_estimate


def test_branches_are_turned_towards_the_configuration_they_are_measured_from(kin: ArmKinematics) -> None:
    """fit_limits_toward: every row as fit_limits turns it (whole turns, inside the limits, nearest the reference)."""
    rng = np.random.default_rng(3)
    lower, upper = kin.model.lower, kin.model.upper
    q = rng.uniform(lower, upper, size=(50, len(lower)))
    for reference in (kin.reach.home, rng.uniform(lower, upper), upper - 0.1):
        turned = fit_limits_toward(q, reference, lower, upper)
        expected = np.stack([fit_limits(row, reference, lower, upper) for row in q])
        np.testing.assert_allclose(turned, expected, atol=1e-12)
        wraps = (turned - q) / (2 * math.pi)
        np.testing.assert_allclose(wraps, np.round(wraps), atol=1e-9)  # the same angles
