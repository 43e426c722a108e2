"""The tour's ring names the views its next plan chooses among (``TourPlan.then``), and the move to the ring's first
view is planned for them, in a headless scan and in a session alike: the cell is asked with ``then`` = those views'
poses, only for that move, and the arm's move is the look-ahead's."""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np
import pytest

from devices.builtins import make_builtin
from devices.sim import make_sim_cell
from planner import Planner, PlannerConfig, Pose
from workbench import SessionRegistry, WorkbenchSettings
from workbench.evaluation.scan import run_scan

COARSE: dict[str, Any] = {"voxel": {"resolution": 0.02}}
"""A coarse map, the default 400 candidates (with ``tests.helpers.SMALL``'s 60 the side the partitions lock has no
ring view in an open sector, and the ring names none)."""


def spy_on_moves(monkeypatch: pytest.MonkeyPatch, cell: Any) -> list[list[Pose]]:
    """The ``then`` of every ``cell.move_to`` call, in order (the call itself goes through)."""
    calls: list[list[Pose]] = []
    move_to = cell.move_to

    def spy(
        T_table_camera: Pose,
        plate_angle: float | None = None,
        then: Any = (),
        motion: Any = None,
        capture_hz: float = 0.0,
        on_frame: Any = None,
    ) -> Any:
        calls.append(list(then))
        return move_to(T_table_camera, plate_angle, then, motion, capture_hz=capture_hz, on_frame=on_frame)

    monkeypatch.setattr(cell, "move_to", spy)
    return calls


def same_poses(a: list[Pose], b: list[Pose]) -> bool:
    return len(a) == len(b) and all(np.allclose(p.matrix, q.matrix) for p, q in zip(a, b, strict=True))


def test_a_headless_tour_scan_plans_the_rings_first_move_for_its_other_side(monkeypatch: pytest.MonkeyPatch) -> None:
    cell = make_sim_cell(make_builtin("l-block"), seed=0)  # the UR5 cell
    assert cell.kinematics is not None
    calls = spy_on_moves(monkeypatch, cell)
    config = PlannerConfig().replace(**COARSE, termination={"max_views": 3})
    result = run_scan(Planner(config, evaluator="tour"), cell, keep_plans=True)
    first_ring, second_ring = result.plans[0], result.plans[1]
    assert first_ring.tour is not None and first_ring.tour.method == "ring" and first_ring.tour.then
    assert second_ring.tour is not None and second_ring.tour.method == "ring" and second_ring.tour.then == ()
    assert calls[0] == []  # the first view: no plan
    named = first_ring.then_poses(first_ring.best_index)
    assert same_poses(calls[1], named) and len(named) == len(first_ring.tour.then)
    assert calls[2] == []  # the ring's last view: nothing named after it
    assert first_ring.then_poses(None) == [] and second_ring.then_poses(second_ring.best_index) == []
    # without the look-ahead no move is asked with one
    cell = make_sim_cell(make_builtin("l-block"), seed=0)
    calls = spy_on_moves(monkeypatch, cell)
    run_scan(Planner(config.replace(tour={"lookahead": False}), evaluator="tour"), cell)
    assert calls == [[], [], []]


def test_a_session_approve_moves_as_the_headless_scan(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    """The approve of the ring's first view moves the arm to the look-ahead's target (the cell asked with the
    plan's named views), the move the page previews; for the sphere it is not the plain shortest move (3.61 s
    against 3.25 s, for a shorter next one)."""
    registry = SessionRegistry(WorkbenchSettings(data_dir=tmp_path, workers=False))
    try:
        session = registry.create(model="sphere", config=COARSE, seed=0, planner="tour")
        session.capture()
        entry = session.plan()
        best = entry.plan.best_index
        assert entry.plan.tour is not None and entry.plan.tour.method == "ring" and entry.plan.tour.then
        named = entry.plan.then_poses(best)
        pose = entry.plan.candidates[best].T_world_camera
        preview = session.cell.plan_motion(pose, then=named)  # what the page shows before the approve
        plain = session.cell.plan_motion(pose)
        calls = spy_on_moves(monkeypatch, session.cell)
        session.approve(entry.plan_id, best)
        assert len(calls) == 1 and same_poses(calls[0], named)
        moved = session.cell.last_motion
        assert moved is not None and np.allclose(moved.q, preview.q) and moved.angle == pytest.approx(preview.angle)
        assert not np.allclose(moved.q, plain.q) and moved.duration > plain.duration
    finally:
        registry.close()
