"""A plan reports where it is: its stages in order (k of n), the items of each, ending at 100 %; reporting
changes nothing in the plan."""

from __future__ import annotations

import copy

import numpy as np
import pytest

from devices.builtins import make_builtin
from devices.config import CameraConfig, CellConfig
from devices.sim import make_sim_cell
from planner import Planner, PlannerConfig
from planner.progress import PlanProgress, Stages
from planner.types import DepthFrame

SMALL = PlannerConfig().replace(voxel={"resolution": 0.02}, candidates={"count": 80}, cluster={"t_min": 2, "t_max": 6})


@pytest.fixture(scope="module")
def frame() -> DepthFrame:
    cell = make_sim_cell(make_builtin("l-block"), CameraConfig(), CellConfig(kinematics="reach_sphere"), seed=0)
    cell.move_to(cell.initial_pose())
    return cell.capture()


@pytest.fixture(scope="module")
def planner(frame: DepthFrame) -> Planner:
    p = Planner(SMALL.replace(cluster={"search": "exhaustive"}))
    p.integrate(frame)
    return p


def in_order(seen: list[PlanProgress]) -> list[str]:
    """The stage names as they came, each once."""
    return [p.stage for i, p in enumerate(seen) if i == 0 or seen[i - 1].stage != p.stage]


def test_a_plan_reports_its_stages_in_order_with_their_items(planner: Planner) -> None:
    seen: list[PlanProgress] = []
    reached = []

    def reachable(pose) -> bool:
        reached.append(pose)
        return pose.translation[0] > 0  # half the hemisphere

    plan = copy.deepcopy(planner).plan(reachable=reachable, progress=seen.append)
    names = ["candidates", "reachability", "fit occupied", "fit frontier", "score", "select"]
    assert in_order(seen) == names
    assert {p.steps for p in seen} == {len(names)}
    assert all(names.index(p.stage) + 1 == p.step for p in seen)
    reach = [p for p in seen if p.stage == "reachability"]
    assert [p.done for p in reach] == list(range(len(plan.candidates))) and {p.total for p in reach} == {80}
    fits = [p for p in seen if p.stage == "fit occupied" and p.total > 1]
    assert [p.done for p in fits] == list(range(6)) and fits[0].total == 5  # T = 2..6, then its end
    fractions = [p.fraction for p in seen]
    assert fractions == sorted(fractions) and fractions[-1] == 1.0 and fractions[0] == 0.0
    assert len(reached) == len(plan.candidates)


def test_reporting_changes_nothing(planner: Planner) -> None:
    quiet = copy.deepcopy(planner).plan()
    loud = copy.deepcopy(planner).plan(progress=lambda p: None)
    assert quiet.best_index == loud.best_index
    np.testing.assert_array_equal([s.score for s in quiet.scores], [s.score for s in loud.scores])


def test_the_baselines_report_their_ray_casting_by_batch(frame: DepthFrame) -> None:
    seen: list[PlanProgress] = []
    baseline = Planner(SMALL, evaluator="raycast-oa")
    baseline.integrate(frame)
    baseline.plan(progress=seen.append)
    rays = [p for p in seen if p.stage == "ray casting"]
    assert in_order(seen) == ["candidates", "ray casting", "select"]
    assert rays[-1].done == rays[-1].total == 80 and len(rays) >= 2


def test_an_unnamed_stage_is_added_at_the_end() -> None:
    seen: list[PlanProgress] = []
    stages = Stages(["a", "b"], seen.append)
    stages("a", 1, 2)
    stages("c", 0, 4)
    assert [(p.stage, p.step, p.steps) for p in seen] == [("a", 1, 2), ("c", 3, 3)]
    assert seen[0].fraction == pytest.approx(0.25) and seen[1].fraction == pytest.approx(2 / 3)
