"""selection.move_cost_weight: 0 is the paper's greedy rule; > 0 trades F against the move time."""

from __future__ import annotations

import numpy as np
import pytest

from planner import Planner, PlannerConfig
from planner.config import SelectionConfig
from planner.partitions import select_best, select_with_move_cost
from planner.types import ViewScore


def score(index: int, f: float, eligible: bool = True) -> ViewScore:
    e = np.zeros(0)
    return ViewScore(index, f, max(f, 0.0), max(-f, 0.0), eligible, e.astype(np.int64), e, e, e)


def test_weight_zero_is_the_greedy_rule() -> None:
    scores = [score(0, 10.0), score(1, 12.0), score(2, 11.0)]
    times = np.array([1.0, 30.0, 2.0])
    assert select_with_move_cost(scores, times, 0.0) == select_best(scores) == 1


def test_a_weight_trades_f_against_the_move_time() -> None:
    scores = [score(0, 10.0), score(1, 12.0), score(2, 11.0), score(3, 100.0, eligible=False)]
    times = np.array([1.0, 30.0, 2.0, 0.1])
    # F / 12 - w * t / 30: view 1 = 1 - w, view 2 = 0.917 - 0.067 w, view 0 = 0.833 - 0.033 w
    assert select_with_move_cost(scores, times, 0.05) == 1
    assert select_with_move_cost(scores, times, 0.5) == 2
    # unknown times are not chosen while another view has one; all unknown falls back to F
    assert select_with_move_cost(scores, np.array([np.inf, np.inf, 2.0, 0.1]), 0.5) == 2
    assert select_with_move_cost(scores, np.full(4, np.inf), 0.5) == 1
    with pytest.raises(ValueError, match=r"^move_seconds: expected shape \(4,\)"):
        select_with_move_cost(scores, np.ones(3), 0.5)


def test_bad_weight_names_the_field() -> None:
    with pytest.raises(ValueError, match=r"^selection\.move_cost_weight:"):
        SelectionConfig(move_cost_weight=-1.0)
    assert PlannerConfig.from_dict({"selection": {"move_cost_weight": 0.3}}).selection.move_cost_weight == 0.3


def test_the_planner_asks_the_caller_for_costs_only_with_a_weight() -> None:
    from devices.builtins import make_builtin
    from devices.config import CellConfig
    from devices.sim import make_sim_cell

    cell = make_sim_cell(make_builtin("l-block"), cell_config=CellConfig(kinematics="reach_sphere"))
    calls: list[int] = []

    def costs(candidates, eligible):
        calls.append(int(np.sum(eligible)))
        return np.arange(len(candidates), dtype=np.float64)[::-1].copy()  # the last candidate is the quickest

    greedy = Planner(PlannerConfig())
    greedy.integrate(cell.capture())
    plan = greedy.plan(reachable=cell.is_reachable, move_cost=costs)
    assert calls == [] and plan.move_costs is None

    weighted = Planner(PlannerConfig.from_dict({"selection": {"move_cost_weight": 100.0}}))
    weighted.integrate(cell.capture())
    plan = weighted.plan(reachable=cell.is_reachable, move_cost=costs)
    assert len(calls) == 1 and calls[0] > 0 and plan.move_costs is not None
    eligible = [s.index for s in plan.scores if s.eligible]
    assert plan.best_index == max(eligible)  # a heavy weight picks the quickest eligible move
