"""A session with capture during moves: the frames of each move go into the map before its view, are journaled with
the view, and a resumed session rebuilds the same map (and the same surface); a discarded view takes its move frames
with it."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from test_durability_model import CAMERA, TINY

from devices.config import CellConfig, DeviceConfig
from planner.config import PlannerConfig
from workbench.journal.store import read_journal, sessions_dir
from workbench.registry.registry import SessionRegistry
from workbench.session.session import Session
from workbench.settings import WorkbenchSettings


def _settings(tmp_path: Path, hz: float) -> WorkbenchSettings:
    return WorkbenchSettings(
        models_dir=tmp_path / "models",
        data_dir=tmp_path / "data",
        workers=False,
        planner=PlannerConfig().replace(**TINY),
        devices=DeviceConfig(camera=CAMERA, cell=CellConfig(move_capture_hz=hz, move_capture_min_new=0.0)),
    )


def _approve_best(session: Session) -> None:
    entry = session.plan()
    assert entry.plan.best_index is not None
    session.approve(entry.plan_id, entry.plan.best_index)


@pytest.mark.slow
def test_move_frames_are_journaled_with_their_view_and_a_resume_rebuilds_the_same_map(tmp_path: Path) -> None:
    settings = _settings(tmp_path, 1.0)
    registry = SessionRegistry(settings)
    session = registry.create("l-block", seed=0)
    session.capture()
    _approve_best(session)
    sid = session.id
    counts = [it["move_frames"] for it in session.record.iterations]
    assert counts[0] == 0 and counts[1] > 0  # the first view has no move; the second brought frames
    assert session.planner.iteration == 2  # move frames are no views
    cloud, voxels = session.planner.cloud.copy(), session.planner.voxel_map.classes.copy()
    fscore = session.record.iterations[-1]["surface_fscore_5mm"]
    journal = read_journal(sessions_dir(settings.data_dir) / sid)
    captures = journal.of_kind("capture")
    stored = [m for ev in captures for m in ev.get("move_frames", [])]
    assert len(stored) == sum(counts)
    assert all((journal.directory / m["frame"]).is_file() for m in stored)
    block = captures[1]["move_capture"]
    assert block["taken"] >= block["kept"] == counts[1] and block["move_seconds"] > 0
    assert block["integration_seconds"] >= 0 and block["wait_seconds"] >= 0
    registry.close()

    registry = SessionRegistry(settings)
    resumed, rebuilt = registry.resume(sid)
    assert rebuilt.mismatches == [] and rebuilt.dropped == []
    np.testing.assert_array_equal(resumed.planner.voxel_map.classes, voxels)
    assert len(resumed.planner.cloud) == len(cloud)
    np.testing.assert_allclose(resumed.planner.cloud, cloud, atol=1e-9)
    assert [it["move_frames"] for it in resumed.record.iterations] == counts
    assert resumed.record.iterations[-1]["surface_fscore_5mm"] == fscore

    resumed.discard_last_view()  # the view and the frames of the move to it
    assert resumed.planner.iteration == 1
    assert len(resumed.planner.cloud) == captures[0]["points"]
    registry.close()


def test_without_capture_during_moves_nothing_changes(tmp_path: Path) -> None:
    settings = _settings(tmp_path, 0.0)
    registry = SessionRegistry(settings)
    session = registry.create("l-block", seed=0)
    session.capture()
    _approve_best(session)
    journal = read_journal(sessions_dir(settings.data_dir) / session.id)
    assert all("move_frames" not in ev for ev in journal.of_kind("capture"))
    assert [it["move_frames"] for it in session.record.iterations] == [0, 0]
    registry.close()
