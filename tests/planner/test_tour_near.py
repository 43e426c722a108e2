"""The ``tour`` planner's projection mode (``tour.score = "projection"``): the shortest move among the views scoring
nearly the best F (``near_best``), the cell's exact move times it asks, and a plan that checks reachability only of
the views it times."""

from __future__ import annotations

import math

import numpy as np
import pytest

from planner import Planner, PlannerConfig
from planner.config import TourConfig
from planner.tour import near_best


def timer(seconds: dict[int, float], calls: list[list[int]]):
    """A ``seconds`` callable of :func:`near_best` with known move times, recording each batch it is asked."""

    def f(views: list[int]) -> np.ndarray:
        calls.append(list(views))
        return np.array([seconds[v] for v in views])

    return f


def test_near_best_takes_the_shortest_move_among_the_views_within_the_slack() -> None:
    ranked = [(7, 10.0), (3, 9.5), (5, 9.2), (1, 8.0)]
    moves = {7: 4.0, 3: 2.5, 5: 1.0, 1: 0.2}
    calls: list[list[int]] = []
    best, timed = near_best(ranked, timer(moves, calls), slack=0.1, near_views=8)
    assert best == 5  # not 1 (the shortest move, but F 8 < 0.9 x 10) and not 7 (the best F, 4 s away)
    assert timed == {7: 4.0, 3: 2.5, 5: 1.0} and calls == [[7, 3, 5]]
    assert near_best(ranked, timer(moves, []), slack=0.0, near_views=8)[0] == 7  # no slack: the best F
    assert near_best(ranked, timer(moves, []), slack=0.25, near_views=8)[0] == 1
    tie = {7: 1.0, 3: 1.0, 5: 1.0, 1: 1.0}
    assert near_best(ranked, timer(tie, []), slack=0.1, near_views=8)[0] == 7  # a tie: the better F


def test_near_best_times_more_views_while_too_few_are_reachable() -> None:
    ranked = [(0, 10.0), (1, 9.9), (2, 9.8), (3, 9.7), (4, 5.0)]
    moves = {0: math.inf, 1: 3.0, 2: 2.0, 3: 0.5, 4: 0.1}
    calls: list[list[int]] = []
    best, timed = near_best(ranked, timer(moves, calls), slack=0.1, near_views=2)
    assert calls == [[0, 1], [2, 3]] and best == 3  # 4 is below the slack: never timed
    assert timed[0] == math.inf and set(timed) == {0, 1, 2, 3}
    unreachable = dict.fromkeys(moves, math.inf)
    assert near_best(ranked, timer(unreachable, []), slack=0.1, near_views=2) == (
        None,
        dict.fromkeys(range(4), math.inf),
    )
    assert near_best([], timer({}, []), 0.1, 2) == (None, {})
    low = [(0, -1.0), (1, -2.0)]  # no view adds anything: the shortest move of those timed
    assert near_best(low, timer({0: 2.0, 1: 1.0}, []), slack=0.1, near_views=2)[0] == 1


def test_the_projection_mode_validates_its_settings() -> None:
    with pytest.raises(ValueError, match=r"^tour\.score:"):
        TourConfig(score="zbuffer")  # type: ignore[arg-type]
    with pytest.raises(ValueError, match=r"^tour\.slack:"):
        TourConfig(slack=1.0)
    with pytest.raises(ValueError, match=r"^tour\.near_views:"):
        TourConfig(near_views=0)


def test_exact_move_times_are_the_moves_the_arm_would_make() -> None:
    from devices.builtins import make_builtin
    from devices.sim import make_sim_cell
    from planner.candidates import propose_candidates
    from planner.types import BoundingBox

    cell = make_sim_cell(make_builtin("l-block", 0.2))
    box = BoundingBox(np.array([-0.1, -0.1, 0.0]), np.array([0.1, 0.1, 0.2]))
    cell.set_object_box(box)
    cfg = PlannerConfig()
    candidates, _, _ = propose_candidates(box, cfg.candidates, cfg.partitions)
    views = [i for i in range(0, len(candidates), 37) if cell.is_reachable(candidates[i].T_world_camera)][:6]
    exact = cell.move_times(candidates, views, exact=True)
    cached = cell.move_times(candidates, views)
    assert cell.kinematics is not None and len(views) >= 4
    q0, a0 = cell.arm.joint_positions(), cell.turntable.angle
    for k, i in enumerate(views, start=1):
        target, _ = cell.kinematics.reach.best_target(candidates[i].T_world_camera, q0, a0)
        assert target is not None and exact[0, k] == pytest.approx(target.move_estimate)
        assert exact[0, k] <= cached[0, k] + 1e-3  # every branch from here: never longer than the cached target
    assert np.any(exact[0, 1:] < cached[0, 1:] - 0.1)  # and here some are shorter by more than 0.1 s


def test_a_projection_mode_plan_checks_reachability_only_of_the_views_it_times() -> None:
    from devices.builtins import make_builtin
    from devices.config import CellConfig
    from devices.sim import make_sim_cell

    cell = make_sim_cell(make_builtin("l-block"), cell_config=CellConfig(kinematics="reach_sphere"))
    config = PlannerConfig().replace(tour={"score": "projection", "slack": 0.2, "near_views": 4})
    reference = Planner(config, evaluator="projection")
    planner = Planner(config, evaluator="tour")
    frame = cell.capture()
    reference.integrate(frame)
    planner.integrate(frame)
    asked: list[int] = []

    def reachable(T) -> bool:
        asked.append(1)
        return cell.is_reachable(T)

    plan = planner.plan(reachable=reachable, move_times=cell.move_times)
    ref = reference.plan(reachable=cell.is_reachable)
    assert not asked  # no reachability pass: the moves timed are the check
    assert plan.move_costs is not None and plan.tour is not None and plan.tour.method == "near"
    timed = np.flatnonzero(np.isfinite(plan.move_costs))
    best = plan.best_index
    assert best is not None and len(timed) >= 1 and best in timed
    assert plan.move_costs[best] == min(plan.move_costs[timed])
    best_f = max(s.score for s in ref.scores if s.eligible)
    assert plan.scores[best].score >= 0.8 * best_f  # the same F as projection's, within the slack
    assert [s.score for s in plan.scores] == [s.score for s in ref.scores]


def test_lazy_reach_covers_again_without_a_view_the_cell_cannot_reach() -> None:
    from planner.baselines.evaluators import gain_scores
    from planner.tour import TourEvaluator
    from planner.types import Pose

    seen = np.array(
        [
            [1, 1, 1, 1, 0, 0],  # view 0: the largest gain, but unreachable
            [1, 1, 1, 0, 0, 0],
            [0, 0, 0, 1, 1, 1],
            [0, 0, 0, 0, 1, 1],
        ],
        dtype=bool,
    )
    at = np.array([0.0, 1.0, 2.0, 3.0])  # the views on a line, state 0 at 0.5; view 0 unreachable

    def move_times(candidates: object, views: list[int]) -> np.ndarray:
        x = np.concatenate([[0.5], at[views]])
        t = np.abs(x[:, None] - x[None, :])
        bad = [k + 1 for k, v in enumerate(views) if v == 0]
        t[bad, :] = math.inf
        t[:, bad] = math.inf
        np.fill_diagonal(t, 0.0)
        return t

    scores = gain_scores(seen.sum(axis=1).astype(np.float64), np.ones(4, dtype=bool))
    for lazy, cover in ((True, {1, 2}), (False, {2})):
        evaluator = TourEvaluator(PlannerConfig().replace(tour={"lazy_reach": lazy, "min_gain": 0.0}))
        evaluator.last_seen = seen
        best, tour = evaluator.choose(scores, [], Pose.identity(), move_times)
        assert tour is not None and set(tour.views) == cover and best == tour.views[0]
        assert evaluator.last_move_seconds[0] == math.inf
    # lazy: 0 left out, the cover made again of 1 and 2 (3 voxels each); without: 0 dropped from the cover {0, 2}


def test_lazy_reach_never_falls_back_to_a_view_found_unreachable() -> None:
    """When every view that gains is unreachable the cover empties: the fallback (the best score) skips the views
    the cell refused, and with none left there is no next view (never one known to be unreachable)."""
    from planner.baselines.evaluators import gain_scores
    from planner.tour import TourEvaluator
    from planner.types import Pose

    seen = np.array([[1, 1, 0], [0, 1, 1], [0, 0, 0]], dtype=bool)  # view 2 sees nothing new

    def move_times(unreachable: set[int]):
        def f(candidates: object, views: list[int]) -> np.ndarray:
            t = np.ones((len(views) + 1, len(views) + 1))
            bad = [k + 1 for k, v in enumerate(views) if v in unreachable]
            t[bad, :] = math.inf
            t[:, bad] = math.inf
            np.fill_diagonal(t, 0.0)
            return t

        return f

    scores = gain_scores(np.array([5.0, 4.0, 1.0]), np.ones(3, dtype=bool))
    evaluator = TourEvaluator(PlannerConfig().replace(tour={"lazy_reach": True, "min_gain": 0.0}))
    evaluator.last_seen = seen
    assert evaluator.choose(scores, [], Pose.identity(), move_times({0, 1})) == (2, None)  # 0 and 1 refused
    scores = gain_scores(np.array([5.0, 4.0, 1.0]), np.array([True, True, False]))
    assert evaluator.choose(scores, [], Pose.identity(), move_times({0, 1})) == (None, None)
