"""A session's metrics carry each view's robot seconds (its move, capture and plan), and the robot time to 90 / 95 %
of the ceiling once the ceiling is known."""

from __future__ import annotations

from pathlib import Path

import pytest

from tests.helpers import SMALL
from workbench import SessionRegistry, WorkbenchSettings


def test_each_view_has_its_robot_seconds(tmp_path: Path) -> None:
    registry = SessionRegistry(WorkbenchSettings(data_dir=tmp_path, workers=False))
    try:
        session = registry.create(model="l-block", config=SMALL, seed=0)
        session.capture()
        entry = session.plan()
        assert entry.plan.best_index is not None
        session.approve(entry.plan_id, entry.plan.best_index)
        session.plan()
        views = session.record.iterations
        assert len(views) == 2
        move = session.cell.last_motion
        assert move is not None and move.duration > 0
        second = views[1]
        assert second["move_seconds"] == pytest.approx(move.duration)
        assert second["robot_seconds"] == pytest.approx(
            second["move_seconds"] + second["capture_seconds"] + second["plan_seconds"]
        )
        metrics = session.metrics()
        assert [v["robot_seconds"] for v in metrics["iterations"]] == [v["robot_seconds"] for v in views]
        assert all(isinstance(v["robot_seconds"], float) for v in views)
        assert metrics["robot_seconds"] == pytest.approx(
            [views[0]["robot_seconds"], views[0]["robot_seconds"] + views[1]["robot_seconds"]]
        )
    finally:
        registry.close()
