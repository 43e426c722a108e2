"""Long operations report where they are and can be stopped: a plan's stages (in its worker, and in the server
process), Stop of a running plan (the state goes back, map and pending plan unchanged), a create's stages on
a mesh file, and its cancellation (nothing created, nothing kept), a discard's and a resume's replay."""

from __future__ import annotations

import threading
import time
from pathlib import Path
from typing import Any

import numpy as np
import pytest
import trimesh

from tests.helpers import SMALL, with_small_costs
from workbench.errors import Conflict, Invalid
from workbench.journal.rebuild import REPLAY_STAGE
from workbench.progress import CREATE_STAGES, Progress, Throttle, Tracker
from workbench.registry.creations import resume_id
from workbench.registry.registry import SessionRegistry
from workbench.session.session import Session
from workbench.session.values import SessionEvent
from workbench.settings import WorkbenchSettings

HEAVY: dict[str, Any] = {
    "voxel": {"resolution": 0.01},
    "cluster": {"search": "exhaustive", "t_min": 1, "t_max": 60, "max_iter": 1000, "tol": 1e-8},
    "candidates": {"count": 833, "parallels": 30},
}
"""A plan of tens of seconds on 2 cores (60 exhaustive fits per kind)."""


def progress_log(session: Session) -> list[dict[str, Any]]:
    """Every progress report of ``session`` from now on (None-free: the end is not logged)."""
    seen: list[dict[str, Any]] = []

    def listener(s: Session, event: SessionEvent) -> None:
        if event == SessionEvent.PROGRESS and (p := s.progress_json()) is not None:
            seen.append(p)

    session.listeners.append(listener)
    return seen


def stage_names(seen: list[dict[str, Any]]) -> list[str]:
    return [p["stage"] for i, p in enumerate(seen) if i == 0 or seen[i - 1]["stage"] != p["stage"]]


@pytest.mark.parametrize("workers", [True, False])
def test_a_plan_reports_its_stages_and_ends(tmp_path: Path, workers: bool) -> None:
    registry = SessionRegistry(with_small_costs(WorkbenchSettings(data_dir=tmp_path / "data", workers=workers)))
    try:
        session = registry.create(model="l-block", config=SMALL)
        session.capture()
        seen = progress_log(session)
        entry = session.plan()
        names = stage_names(seen)
        assert names[0] == "starting" and names[1:] == [
            "candidates",
            "reachability",
            "fit occupied",
            "fit frontier",
            "score",
            "select",
        ], names
        assert all(p["operation"] == "plan" and p["stoppable"] is workers for p in seen)
        reach = [p for p in seen if p["stage"] == "reachability"]
        assert reach[-1]["total"] == len(entry.plan.candidates)  # the candidates are counted
        percents = [p["percent"] for p in seen]
        assert percents == sorted(percents) and percents[-1] == 100.0
        assert session.progress_json() is None and session.status()["progress"] is None  # it ended
    finally:
        registry.close()


def test_stop_kills_a_running_plan_and_puts_the_state_back(tmp_path: Path) -> None:
    registry = SessionRegistry(WorkbenchSettings(data_dir=tmp_path / "data"))
    try:
        session = registry.create(model="l-block", config=HEAVY)
        session.capture()
        assert session.state == "ready" and session.pending is None
        seen = progress_log(session)
        box: dict[str, Any] = {}

        def run() -> None:
            try:
                box["plan"] = session.plan()
            except Exception as exc:
                box["error"] = exc

        thread = threading.Thread(target=run)
        thread.start()
        deadline = time.monotonic() + 60
        while not any(p["stage"] == "fit occupied" for p in seen):
            assert time.monotonic() < deadline and thread.is_alive(), box
            time.sleep(0.02)
        assert session.state == "planning" and session.progress_json()["stoppable"]
        pid = session.worker.pid
        voxels = session.planner.voxel_map.classes.copy()
        t0 = time.monotonic()
        assert session.stop_plan()
        thread.join(10)
        assert time.monotonic() - t0 < 2.0 and not thread.is_alive()
        assert isinstance(box.get("error"), Conflict) and "stopped" in str(box["error"]), box
        assert session.state == "ready" and session.pending is None and session.status()["error"] is None
        assert np.array_equal(session.planner.voxel_map.classes, voxels)
        assert pid is not None and session.worker.pid is None and session.progress_json() is None
        assert not session.stop_plan()  # nothing runs now
    finally:
        registry.close()


def sphere_file(models: Path, subdivisions: int) -> str:
    models.mkdir(parents=True, exist_ok=True)
    trimesh.creation.icosphere(subdivisions=subdivisions, radius=0.05).export(models / "ball.obj")
    return "ball.obj"


def test_a_create_on_a_mesh_file_reports_its_stages(tmp_path: Path) -> None:
    settings = WorkbenchSettings(data_dir=tmp_path / "data", models_dir=tmp_path / "models", workers=False)
    name = sphere_file(settings.models_dir, 5)
    registry = SessionRegistry(settings)
    seen: list[tuple[str, Progress | None]] = []
    registry.creations.listeners.append(lambda pid, p: seen.append((pid, p)))
    try:
        registry.create(model=name, config=SMALL, progress_id="page-0001")
        assert {pid for pid, _ in seen} == {"page-0001"}
        reports = [p for _, p in seen if p is not None]
        names = [p.stage for i, p in enumerate(reports) if i == 0 or reports[i - 1].stage != p.stage]
        assert names == list(CREATE_STAGES)
        assert [p.step for p in reports] == sorted(p.step for p in reports) and reports[-1].steps == 6
        assert seen[-1] == ("page-0001", None) and registry.creations.progress("page-0001") is None
        registry.create(model=name, config=SMALL)  # without an id: nobody hears
        assert len(seen) == len(names) + 1
        with pytest.raises(Invalid, match="progress_id"):
            registry.create(model=name, config=SMALL, progress_id="bad id!")
    finally:
        registry.close()


def test_a_cancelled_create_leaves_nothing(tmp_path: Path) -> None:
    settings = WorkbenchSettings(data_dir=tmp_path / "data", models_dir=tmp_path / "models", workers=False)
    name = sphere_file(settings.models_dir, 5)
    registry = SessionRegistry(settings)

    def cancel_when_reading(pid: str, p: Progress | None) -> None:
        if p is not None and p.stage == "reading the mesh":
            assert registry.creations.cancel(pid)

    registry.creations.listeners.append(cancel_when_reading)
    try:
        with pytest.raises(Conflict, match="cancelled"):
            registry.create(model=name, config=SMALL, progress_id="page-0002")
        assert registry.list() == [] and not list((settings.data_dir / "sessions").glob("*/journal.jsonl"))
        assert not registry.creations.cancel("page-0002")  # it ended
    finally:
        registry.close()


def test_the_tracker_sends_stage_changes_and_ends_but_throttles_items() -> None:
    sent: list[Progress | None] = []
    tracker = Tracker(sent.append, interval=60.0)
    tracker.begin("plan")
    for i in range(100):
        tracker.stage("reachability", i, 100)
    tracker.stage("reachability", 100, 100)
    tracker.stage("score", 0, 5)
    tracker.end()
    assert [None if p is None else (p.stage, p.done) for p in sent] == [
        ("starting", 0),
        ("reachability", 0),
        ("reachability", 100),
        ("score", 0),
        None,
    ]
    throttle = Throttle(0.0)
    assert all(throttle("a", i, 10) for i in range(10))  # no interval: every report goes


def test_a_discard_and_a_resume_report_the_journal_they_replay(tmp_path: Path) -> None:
    settings = with_small_costs(WorkbenchSettings(data_dir=tmp_path / "data", workers=False))
    registry = SessionRegistry(settings)
    try:
        session = registry.create(model="l-block", config=SMALL)
        session.capture()
        session.auto.step(3)  # 4 views, 3 plans
        seen = progress_log(session)
        session.discard_last_view()  # replays 3 captures and 3 plans (the 4th capture left out)
        assert {p["operation"] for p in seen} == {"discard"} and stage_names(seen) == [REPLAY_STAGE]
        done = [p["done"] for p in seen]  # throttled to 10 a second: the first and the last at least
        assert (
            done == sorted(done) and (done[0], done[-1]) == (0, 6) and {p["total"] for p in seen[1:]} == {6}
        )  # after the start
        assert session.progress_json() is None
        assert session.journal is not None
        session.journal.close()  # the server "stops"
        other = SessionRegistry(settings)
        heard: list[tuple[str, Progress | None]] = []
        other.creations.listeners.append(lambda pid, p: heard.append((pid, p)))
        other.resume(session.id)
        assert {pid for pid, _ in heard} == {resume_id(session.id)} and heard[-1][1] is None
        reports = [p for _, p in heard if p is not None]
        assert {p.operation for p in reports} == {"resume"} and not any(p.stoppable for p in reports)
        done = [p.done for p in reports if p.stage == REPLAY_STAGE]
        assert done == sorted(done) and (done[0], done[-1]) == (0, 6)
        other.close()
        with pytest.raises(Invalid, match="resume-"):
            registry.create(model="l-block", config=SMALL, progress_id=resume_id("12345678"))
    finally:
        registry.close()


def test_a_resume_replays_its_journal_in_the_worker(tmp_path: Path) -> None:
    """With workers (the server's default) the journal is replayed in the session's worker, bounded and killable
    like its plans: the rebuilt map and pending plan equal the live session's, with no mismatch."""
    settings = with_small_costs(WorkbenchSettings(data_dir=tmp_path / "data"))
    registry = SessionRegistry(settings)
    try:
        session = registry.create(model="l-block", config=SMALL)
        session.capture()
        session.auto.step(2)
        live = session.plan()
        assert session.journal is not None
        session.journal.close()
        other = SessionRegistry(settings)
        try:
            wb, rebuilt = other.resume(session.id)
            assert wb.worker is not None and wb.worker.jobs == 1  # the rebuild was its worker's first job
            assert rebuilt.mismatches == [] and rebuilt.dropped == []
            assert np.array_equal(wb.planner.voxel_map.classes, session.planner.voxel_map.classes)
            assert wb.pending is not None and wb.pending.plan_id == live.plan_id
            assert wb.pending.plan.best_index == live.plan.best_index
            assert [s.score for s in wb.pending.plan.scores] == [s.score for s in live.plan.scores]
            assert wb.cell.joint_positions() is not None and np.allclose(
                wb.cell.joint_positions(), session.cell.joint_positions()
            )  # the arm where the session left it
        finally:
            other.close()
    finally:
        registry.close()
