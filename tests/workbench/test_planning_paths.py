"""Planning in a cell that captures during its moves: the planner gets the cell's camera paths, at most at the
cell's rate; a cell that does not capture gives none."""

from __future__ import annotations

import dataclasses

from devices.builtins import make_builtin
from devices.config import CameraConfig, CellConfig
from devices.sim import make_sim_cell
from planner import Planner, PlannerConfig
from planner.paths import PathEvaluator
from workbench.planning import move_paths_of, plan_in

SMALL = PlannerConfig().replace(voxel={"resolution": 0.02}, candidates={"count": 80})
CAMERA = CameraConfig(width=80, height=60, fx=76.0, fy=76.0, cx=39.5, cy=29.5)


def test_a_cell_that_captures_during_moves_gives_the_planner_its_paths_at_its_rate() -> None:
    config = CellConfig(kinematics="reach_sphere", move_capture_hz=1.0)
    cell = make_sim_cell(make_builtin("box"), CAMERA, config, seed=0)
    cell.move_to(cell.initial_pose())
    planner = Planner(SMALL, "path")  # path.sample_hz 2.5: the cell's 1 Hz is the most it will take
    planner.integrate(cell.capture())
    plan = plan_in(cell, planner)
    evaluator = planner.evaluator
    assert isinstance(evaluator, PathEvaluator)
    assert plan.best_index is not None and plan.tour is not None and plan.tour.method == "path"
    path = evaluator.last_paths[plan.best_index]
    assert path.seconds > 1.0 and len(path) == int(path.seconds)  # frames at 1, 2, ... s strictly inside the move
    cell.config = dataclasses.replace(config, move_capture_hz=0.0)
    assert move_paths_of(cell) is None
    plan_in(cell, planner)
    assert evaluator.last_paths == {}  # no capture: the views alone, per second of their moves
    assert evaluator.last_rates
