"""The tour's ring opening (``tour.opening = "ring"``, planner/tour.py): a turntable scanner's ring of low views
either side of the scan's first view, before the tour."""

from __future__ import annotations

import math

import numpy as np
import pytest

from planner import Planner, PlannerConfig
from planner.partitions import azimuth_of
from planner.tour import azimuth_gap, low_views, other_side, ring_directions, ring_view

DEG = math.pi / 180.0


def test_ring_directions_stay_open_until_a_view_is_taken_near_them() -> None:
    first, spread, tol = 350 * DEG, 120 * DEG, 30 * DEG
    assert np.allclose(ring_directions(first, spread, [], tol), [110 * DEG, 230 * DEG])
    # a view 25 degrees from one side (across 0 / 360 from the other) closes only that side
    assert np.allclose(ring_directions(first, spread, [255 * DEG], tol), [110 * DEG])
    assert np.allclose(ring_directions(first, spread, [141 * DEG], tol), [110 * DEG, 230 * DEG])  # 31: still open
    assert ring_directions(first, spread, [100 * DEG, 220 * DEG], tol) == []
    assert np.allclose(ring_directions(0.0, math.pi, [], tol), [math.pi])  # both sides meet behind the object
    assert azimuth_gap(np.array([355 * DEG]), 5 * DEG) == pytest.approx(10 * DEG)


def test_ring_view_takes_the_shortest_move_among_the_low_ring_views_that_see_most() -> None:
    #                  0     1     2     3     4     5     6
    azimuths = np.array([120, 130, 240, 120, 180, 250, 115]) * DEG
    elevations = np.array([10, 20, 10, 60, 10, 0, 5]) * DEG
    counts = np.array([100, 80, 40, 200, 300, 90, 95], dtype=np.float64)
    seconds_of = np.array([4.0, 2.0, 0.5, 0.1, 0.1, math.inf, 0.1])  # 5 unreachable
    eligible = np.array([True, True, True, True, True, True, False])  # 6 taken or refused before
    asked: list[list[int]] = []

    def seconds(views: list[int]) -> np.ndarray:
        asked.append(list(views))
        return seconds_of[views]

    ring = [120 * DEG, 240 * DEG]
    args = (eligible, azimuths, elevations, ring, 30 * DEG, 30 * DEG, 0.5, seconds)
    best, timed = ring_view(counts, *args, 8)
    # 3 is too high, 4 off the ring, 6 not eligible, 2 sees less than half the best ring view (40 < 50)
    assert asked == [[0, 5, 1]] and best == 1
    assert timed == {0: 4.0, 5: math.inf, 1: 2.0}
    asked.clear()
    best, timed = ring_view(counts, *args, 1)  # one reachable view timed: the one that sees most
    assert (best, asked) == (0, [[0]])
    best, timed = ring_view(counts, eligible, azimuths, elevations, [240 * DEG], 30 * DEG, 30 * DEG, 0.5, seconds, 8)
    assert (best, timed) == (None, {5: math.inf})  # the side's only view that sees enough is unreachable
    assert ring_view(counts, eligible, azimuths, elevations, [60 * DEG], 30 * DEG, 30 * DEG, 0.5, seconds, 8) == (
        None,
        {},
    )


def test_the_ring_settings_are_validated() -> None:
    for bad, match in (
        ({"opening": "circle"}, "tour.opening"),
        ({"ring_spread_deg": 0}, "tour.ring_spread_deg"),
        ({"ring_spread_deg": 181}, "tour.ring_spread_deg"),
        ({"ring_max_elevation_deg": math.nan}, "tour.ring_max_elevation_deg"),
        ({"ring_tolerance_deg": -5}, "tour.ring_tolerance_deg"),
        ({"ring_share": 1.5}, "tour.ring_share"),
        ({"ring_share": "half"}, "tour.ring_share"),
        ({"lookahead": "yes"}, "tour.lookahead"),
        ({"cover_max_elevation_deg": 91}, "tour.cover_max_elevation_deg"),
        ({"cover_max_elevation_deg": math.inf}, "tour.cover_max_elevation_deg"),
    ):
        with pytest.raises(ValueError, match=f"^{match}"):
            PlannerConfig.from_dict({"tour": bad})


def scan(opening: str, views: int) -> list[tuple[float, float, str | None]]:
    """(azimuth from the first view, elevation, tour method) of each view the ``tour`` planner chose in a simulated
    reach-sphere cell scanning an L-block; degrees."""
    from devices.builtins import make_builtin
    from devices.config import CellConfig
    from devices.sim import make_sim_cell

    cell = make_sim_cell(make_builtin("l-block"), cell_config=CellConfig(kinematics="reach_sphere"), seed=0)
    planner = Planner(PlannerConfig().replace(tour={"opening": opening}), evaluator="tour")
    cell.move_to(cell.initial_pose())
    out = []
    for _ in range(views):
        planner.integrate(cell.capture())
        plan = planner.plan(reachable=cell.is_reachable, move_times=cell.move_times)
        best = plan.best
        assert best is not None and plan.tour is not None
        center = (plan.bbox.lower + plan.bbox.upper) / 2  # the candidates' centre with the default aim
        first = azimuth_of(planner.views[0].translation, center)
        gap = (best.azimuth - first + math.pi) % (2 * math.pi) - math.pi
        out.append((gap / DEG, best.elevation / DEG, plan.tour.method))
        cell.move_to(best.T_world_camera)
    return out


def test_the_ring_opens_a_scan_with_a_low_view_either_side_of_the_first_then_the_tour() -> None:
    views = scan("ring", 3)
    (a1, e1, m1), (a2, e2, m2), (_, _, m3) = views
    assert (m1, m2) == ("ring", "ring") and m3 != "ring"
    assert e1 <= 30.0 + 1e-6 and e2 <= 30.0 + 1e-6
    # one view within 30 degrees of each side of the ring (+120 and -120 from the first view)
    sides = sorted(np.sign([a1, a2]))
    assert sides == [-1, 1], views
    assert all(abs(abs(a) - 120.0) <= 30.0 + 1e-6 for a in (a1, a2)), views
    assert all(m != "ring" for _, _, m in scan("none", 2))  # without the opening: the tour from the first plan


def ring_candidates(spec: list[tuple[float, float]]) -> list:
    """Candidates at (azimuth, elevation) degrees on a 0.5 m sphere about the origin, looking at it."""
    from planner.types import Candidate, Pose

    out = []
    for i, (a, e) in enumerate(spec):
        a, e = a * DEG, e * DEG
        eye = 0.5 * np.array([math.cos(e) * math.cos(a), math.cos(e) * math.sin(a), math.sin(e)])
        out.append(Candidate(i, Pose.look_at(eye, np.zeros(3)), e, a % (2 * math.pi), 0, 0))
    return out


def test_the_ring_is_chosen_by_exact_moves_in_the_first_two_plans_only() -> None:
    from planner.baselines.evaluators import gain_scores
    from planner.tour import TourEvaluator
    from planner.types import Pose

    #                         0 ring +120   1 ring +110   2 ring -120   3 high     4 the cover's best
    candidates = ring_candidates([(120, 10), (110, 20), (240, 10), (120, 70), (180, 10)])
    seen = np.zeros((5, 40), dtype=bool)
    seen[0, :10] = seen[1, :9] = seen[2, 10:18] = seen[3, :30] = seen[4, :40] = True
    secs = np.array([3.0, 2.5, 2.0, 0.5, 0.5])
    asked: list[tuple[list[int], bool]] = []

    def move_times(cands: object, views: list[int], exact: bool = False) -> np.ndarray:
        asked.append((list(views), exact))
        x = np.concatenate([[0.0], secs[views]])
        return np.abs(x[:, None] - x[None, :])

    evaluator = TourEvaluator(PlannerConfig())
    evaluator.last_seen = seen
    scores = gain_scores(seen.sum(axis=1).astype(np.float64), np.ones(5, dtype=bool))
    first = Pose.look_at(np.array([0.5, 0.0, 0.2]), np.zeros(3))  # the scan's first view, at azimuth 0
    best, plan = evaluator.choose(scores, candidates, first, move_times, taken=[first], center=np.zeros(3))
    # ring views: 0, 1 (+120 side), 2 (-120 side: 8 >= half of 10); 3 too high, 4 off the ring
    assert asked == [([0, 1, 2], True)]
    assert best == 2 and plan is not None and plan.method == "ring" and plan.views == (2,) and plan.seconds == (2.0,)
    assert evaluator.last_move_seconds == {0: 3.0, 1: 2.5, 2: 2.0}
    assert plan.then == (0, 1)  # the other side's ring views, most frontier first: what the move plans for
    alone = TourEvaluator(PlannerConfig().replace(tour={"lookahead": False}))
    alone.last_seen = seen
    _, lone = alone.choose(scores, candidates, first, move_times, taken=[first], center=np.zeros(3))
    assert lone is not None and lone.views == (2,) and lone.then == ()
    # the -120 side taken: the other side's shortest move next
    taken = [first, candidates[2].T_world_camera]
    asked.clear()
    best, plan = evaluator.choose(scores, candidates, taken[-1], move_times, taken=taken, center=np.zeros(3))
    assert (best, plan.method if plan else None, asked) == (1, "ring", [([0, 1], True)])
    assert plan is not None and plan.then == ()  # the ring's last view: nothing named after it
    # both sides held, or a third plan: the tour (the cover's best view first), timed by the cached estimates
    for taken in ([first, candidates[2].T_world_camera, candidates[1].T_world_camera], [first, first, first]):
        asked.clear()
        best, plan = evaluator.choose(scores, candidates, first, move_times, taken=taken, center=np.zeros(3))
        assert plan is not None and plan.method != "ring" and best == 4
        assert all(not exact for _, exact in asked)
    # no opening without the taken views' centre, nor with opening "none"
    best, plan = evaluator.choose(scores, candidates, first, move_times, taken=[first])
    assert plan is not None and plan.method != "ring"
    without = TourEvaluator(PlannerConfig().replace(tour={"opening": "none"}))
    without.last_seen = seen
    _, plan = without.choose(scores, candidates, first, move_times, taken=[first], center=np.zeros(3))
    assert plan is not None and plan.method != "ring"
    assert PlannerConfig().tour.opening == "ring"  # the default


def test_a_ring_view_the_cell_cannot_reach_is_left_out_of_the_cover_too() -> None:
    """The ring's view that sees most is unreachable from here as the cell would move (its exact time is inf) but
    not by the cached estimate the cover orders by: with lazy reachability the cover leaves it out."""
    from planner.baselines.evaluators import gain_scores
    from planner.tour import TourEvaluator
    from planner.types import Pose

    candidates = ring_candidates([(120, 10), (180, 10)])  # 0: the ring's only view, unreachable; 1: off the ring
    seen = np.zeros((2, 40), dtype=bool)
    seen[0, :40] = seen[1, :20] = True

    def move_times(cands: object, views: list[int], exact: bool = False) -> np.ndarray:
        t = np.ones((len(views) + 1, len(views) + 1))
        np.fill_diagonal(t, 0.0)
        if exact and 0 in views:
            k = views.index(0) + 1
            t[k, :] = t[:, k] = math.inf
            t[k, k] = 0.0
        return t

    scores = gain_scores(seen.sum(axis=1).astype(np.float64), np.ones(2, dtype=bool))
    first = Pose.look_at(np.array([0.5, 0.0, 0.2]), np.zeros(3))
    for lazy, expected in ((True, 1), (False, 0)):
        evaluator = TourEvaluator(PlannerConfig().replace(tour={"lazy_reach": lazy}))
        evaluator.last_seen = seen
        best, plan = evaluator.choose(scores, candidates, first, move_times, taken=[first], center=np.zeros(3))
        assert best == expected and plan is not None and plan.method != "ring"
    assert evaluator.last_move_seconds[0] == 1.0  # without lazy reachability the cover's cached time stands


def test_the_projection_score_keeps_its_own_choice_from_the_first_plan() -> None:
    from planner.baselines.evaluators import gain_scores
    from planner.tour import TourEvaluator
    from planner.types import Pose

    candidates = ring_candidates([(120, 10), (180, 10)])  # 0 a ring view, 1 off the ring with the best score
    scores = gain_scores(np.array([5.0, 9.0]), np.ones(2, dtype=bool))

    def move_times(cands: object, views: list[int], exact: bool = False) -> np.ndarray:
        t = np.ones((len(views) + 1, len(views) + 1))
        np.fill_diagonal(t, 0.0)
        return t

    evaluator = TourEvaluator(PlannerConfig().replace(tour={"score": "projection", "slack": 0.1}))
    first = Pose.look_at(np.array([0.5, 0.0, 0.2]), np.zeros(3))
    best, plan = evaluator.choose(scores, candidates, first, move_times, taken=[first], center=np.zeros(3))
    assert best == 1 and plan is not None and plan.method == "near"


def test_the_other_side_names_the_ring_views_the_next_plan_will_time() -> None:
    """The views the ring's next plan chooses among (ring_view's rule, eligibility aside): low, near the other side's
    azimuth, seeing at least half the most any of them sees; the ``near_views`` that see most, most first."""
    #                    0    1    2    3    4    5    6
    azimuths = np.array([240, 250, 235, 240, 120, 230, 300]) * DEG
    elevations = np.array([10, 20, 10, 60, 10, 0, 10]) * DEG
    counts = np.array([50, 80, 30, 500, 400, 80, 90], dtype=np.float64)
    args = (azimuths, elevations, 240 * DEG, 30 * DEG, 30 * DEG, 0.5)
    # 3 too high, 4 the other side, 6 60 degrees off, 2 less than half of 80
    assert other_side(counts, *args, 8) == (1, 5, 0)
    assert other_side(counts, *args, 2) == (1, 5)
    assert other_side(np.zeros(7), *args, 8) == ()  # no ring view sees frontier there


def test_the_cover_takes_low_views_while_one_of_them_sees_frontier() -> None:
    """After the ring, views above ``tour.cover_max_elevation_deg`` (25) are left to the cover only when no lower
    one sees frontier; 90 leaves every view."""
    from planner.baselines.evaluators import gain_scores
    from planner.tour import TourEvaluator
    from planner.types import Pose

    #                              0 high, sees most   1 low          2 low, sees nothing   3 high
    candidates = ring_candidates([(170, 60), (180, 10), (200, 20), (190, 40)])
    seen = np.zeros((4, 40), dtype=bool)
    seen[0, :30] = seen[1, 20:32] = seen[3, :5] = True
    eligible = np.ones(4, dtype=bool)
    assert low_views(eligible, seen, candidates, 25.0).tolist() == [False, True, True, False]
    assert low_views(eligible, seen, candidates, 90.0).tolist() == [True] * 4
    assert low_views(eligible, seen[[0, 2, 2, 3]], candidates, 25.0).tolist() == [True] * 4  # no low view sees any
    assert low_views(~eligible, seen, candidates, 25.0).tolist() == [False] * 4
    assert low_views(eligible, seen, [], 25.0).tolist() == [True] * 4  # elevations unknown: no limit

    def move_times(cands: object, views: list[int], exact: bool = False) -> np.ndarray:
        return np.ones((len(views) + 1, len(views) + 1)) - np.eye(len(views) + 1)

    scores = gain_scores(seen.sum(axis=1).astype(np.float64), eligible)
    first = Pose.look_at(np.array([0.5, 0.0, 0.2]), np.zeros(3))
    taken = [first, first, first]  # the ring is over
    for max_elevation, expected in ((25.0, 1), (90.0, 0)):
        evaluator = TourEvaluator(PlannerConfig().replace(tour={"cover_max_elevation_deg": max_elevation}))
        evaluator.last_seen = seen
        best, plan = evaluator.choose(scores, candidates, first, move_times, taken=taken, center=np.zeros(3))
        assert best == expected and plan is not None and plan.views[0] == expected
