"""A resume keeps the journal whole when views were discarded: the discard and every view after it survive the next
restart too. (A resume cut the journal to as many events as it replayed, and a discarded capture is not replayed:
the discard was cut off and its view came back, or the views acknowledged after it were lost, at the next
restart. Found by the durability model, tests/workbench/test_durability_model.py.)"""

from __future__ import annotations

from pathlib import Path

import pytest
from test_durability_model import CAMERA, TINY

from devices.config import DeviceConfig
from planner.config import PlannerConfig
from workbench.journal.discard import without_discarded
from workbench.journal.store import read_journal, sessions_dir
from workbench.registry.registry import SessionRegistry
from workbench.session.session import Session
from workbench.settings import WorkbenchSettings


def _settings(tmp_path: Path) -> WorkbenchSettings:
    return WorkbenchSettings(
        models_dir=tmp_path / "models",
        data_dir=tmp_path / "data",
        workers=False,
        planner=PlannerConfig().replace(**TINY),
        devices=DeviceConfig(camera=CAMERA),
    )


def _poses(session: Session) -> list[list[float]]:
    return [it["pose"]["position"] for it in session.record.iterations]


def _approve_best(session: Session) -> None:
    entry = session.plan()
    assert entry.plan.best_index is not None
    session.approve(entry.plan_id, entry.plan.best_index)


def _restart_and_resume(
    settings: WorkbenchSettings, registry: SessionRegistry, sid: str
) -> tuple[SessionRegistry, Session]:
    registry.close()
    registry = SessionRegistry(settings)
    session, rebuilt = registry.resume(sid)
    assert rebuilt.dropped == [] and rebuilt.kept == len(read_journal(sessions_dir(settings.data_dir) / sid).events) - 1
    return registry, session


def test_the_only_view_discarded_stays_discarded_over_two_restarts(tmp_path: Path) -> None:
    settings = _settings(tmp_path)
    registry = SessionRegistry(settings)
    session = registry.create("mug", seed=0)
    session.capture()
    session.discard_last_view()
    sid = session.id
    for _ in range(2):
        registry, session = _restart_and_resume(settings, registry, sid)
        assert session.record.iterations == [] and session.planner.iteration == 0
    journal = read_journal(sessions_dir(settings.data_dir) / sid)
    assert [e["kind"] for e in journal.events] == ["capture", "discard", "resume", "resume"]
    registry.close()


@pytest.mark.slow
def test_views_after_a_discard_survive_two_restarts(tmp_path: Path) -> None:
    settings = _settings(tmp_path)
    registry = SessionRegistry(settings)
    session = registry.create("l-block", seed=1)
    session.capture()
    _approve_best(session)
    session.discard_last_view()
    _approve_best(session)  # acknowledged after the discard
    _approve_best(session)
    sid, acknowledged = session.id, _poses(session)
    assert len(acknowledged) == 3
    for _ in range(2):
        registry, session = _restart_and_resume(settings, registry, sid)
        assert _poses(session) == acknowledged
        assert session.planner.iteration == 3
    journal = read_journal(sessions_dir(settings.data_dir) / sid)
    captures = [e for e in without_discarded(journal.events) if e["kind"] == "capture"]
    assert [e["pose_used"]["position"] for e in captures] == acknowledged
    registry.close()
