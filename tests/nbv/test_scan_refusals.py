"""A refused move never ends a headless scan: the next eligible view is taken and the refusal recorded; only
"every eligible view refused" ends it."""

from __future__ import annotations

import dataclasses

from devices.builtins import make_builtin
from devices.config import CameraConfig, CellConfig
from devices.protocols import UnreachableError
from devices.sim import SimulatedCamera, make_sim_cell
from planner import Planner, PlannerConfig, PlanResult
from workbench.evaluation.scan import IterationRecord, run_scan


def small_config(views: int) -> PlannerConfig:
    return PlannerConfig().replace(termination={"max_views": views}, candidates={"count": 60})


def test_a_refused_move_is_recorded_and_the_scan_goes_on() -> None:
    cell = make_sim_cell(make_builtin("l-block"), CameraConfig(), CellConfig(kinematics="reach_sphere"), seed=0)
    refusals = []

    def refuse_once(record: IterationRecord, plan: PlanResult) -> None:
        if record.index == 2:  # the move after view 2 is refused by the arm (after the plate turned)
            cell.arm.fail_next = UnreachableError("unreachable: injected stop", reason="injected")
            refusals.append(plan.best_index)

    result = run_scan(Planner(small_config(4)), cell, on_iteration=refuse_once)
    assert result.terminated == "max_views"
    assert len(result.records) == 4
    third = result.records[2]
    assert third.refused_moves == [
        {"candidate": refusals[0], "reason": "injected", "message": "unreachable: injected stop"}
    ]
    assert result.refused_moves == [{"after_view": 2, **third.refused_moves[0]}]
    assert result.records[1].refused_moves == [] and result.records[3].refused_moves == []
    assert third.to_json()["refused_moves"] == third.refused_moves


def test_only_every_eligible_view_refused_ends_the_scan() -> None:
    cell = make_sim_cell(make_builtin("l-block"), CameraConfig(), CellConfig(kinematics="reach_sphere"), seed=0)
    eligible: list[int] = []

    def shrink_reach(record: IterationRecord, plan: PlanResult) -> None:
        if record.index == 2:  # after the plan was made, the cell can reach nothing any more
            cell.config = dataclasses.replace(cell.config, arm_reach=0.16, arm_min_reach=0.155)
            eligible.append(sum(s.eligible for s in plan.scores))

    result = run_scan(Planner(small_config(6)), cell, on_iteration=shrink_reach)
    assert result.terminated == "no_eligible_view"
    assert len(result.records) == 2
    assert len(result.refused_moves) == eligible[0] > 1  # every eligible view was tried, each refusal recorded
    assert all(r["after_view"] == 2 and "arm_reach" in r["message"] for r in result.refused_moves)


def test_an_empty_frame_is_recorded_and_the_next_view_taken() -> None:
    """A view beyond a short-range sensor's reach gives no usable frame: the scan goes on from the same plan."""
    cell = make_sim_cell(make_builtin("l-block"), CameraConfig(), CellConfig(kinematics="reach_sphere"), seed=0)
    camera = cell.camera
    assert isinstance(camera, SimulatedCamera)
    far: dict[str, int] = {}

    def blind_once(record: IterationRecord, plan: PlanResult) -> None:
        if record.index == 2:  # the next capture sees nothing (a lens cap)
            camera.config = dataclasses.replace(camera.config, max_depth=0.11)
            far["best"] = plan.best_index if plan.best_index is not None else -1

    real_capture = camera.capture

    def capture_then_restore() -> object:
        frame = real_capture()
        camera.config = dataclasses.replace(camera.config, max_depth=1.5)
        return frame

    camera.capture = capture_then_restore  # type: ignore[method-assign]
    result = run_scan(Planner(small_config(4)), cell, on_iteration=blind_once)
    assert result.terminated == "max_views" and len(result.records) == 4
    empty = [r for r in result.refused_moves if r["reason"] == "empty_frame"]
    assert len(empty) == 1 and empty[0]["after_view"] == 2 and empty[0]["candidate"] == far["best"]
    assert result.records[2].refused_moves[0]["reason"] == "empty_frame"
