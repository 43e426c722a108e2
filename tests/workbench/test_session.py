"""The session state machine on a simulated cell, driven as a library (no HTTP, no monkeypatching)."""

from __future__ import annotations

import json

import numpy as np
import pytest

from planner import Pose
from tests.helpers import SMALL, wait_for_state, wait_until
from workbench.errors import Conflict, DeviceFault, Invalid, NotFound, Unreachable
from workbench.journal.store import read_journal
from workbench.registry.registry import SessionRegistry
from workbench.session.states import State
from workbench.session.values import DecisionKind, SessionEvent


def test_the_loop_capture_plan_approve_moves_once_per_plan(registry: SessionRegistry) -> None:
    session = registry.create("l-block", SMALL, seed=1)
    events: list[SessionEvent] = []
    # the state machine's events (a plan's progress reports come in between: tests/workbench/test_progress.py)
    session.listeners.append(lambda _s, event: events.append(event) if event != SessionEvent.PROGRESS else None)
    assert session.state == State.NEW
    with pytest.raises(Conflict, match="no frame yet"):
        session.plan()
    session.capture()
    assert session.state == State.READY and session.moves == 1
    entry = session.plan()
    assert session.state == State.PLANNED and session.pending is entry
    best = entry.plan.best_index
    assert best is not None
    session.approve(entry.plan_id, index=best)
    assert session.state == State.READY and session.moves == 2
    with pytest.raises(Conflict, match="already used"):
        session.approve(entry.plan_id, index=best)
    assert session.moves == 2  # the second approval of one plan moved nothing
    assert events == [
        SessionEvent.STATE,
        SessionEvent.CAPTURED,
        SessionEvent.STATE,
        SessionEvent.PLANNED,
        SessionEvent.STATE,
        SessionEvent.CAPTURED,
    ]
    status = session.status()
    assert status["iteration"] == 2 and status["state"] == "ready" and 0 < status["coverage"] <= 1
    assert status["voxels"]["occupied"] > 0 and status["points"] > 0


def test_a_newer_plan_makes_the_old_one_stale_and_bad_targets_move_nothing(registry: SessionRegistry) -> None:
    session = registry.create("l-block", SMALL)
    session.capture()
    old = session.plan()
    new = session.plan()
    with pytest.raises(Conflict, match="stale"):
        session.approve(old.plan_id, index=0)
    with pytest.raises(NotFound, match="candidate 999"):
        session.approve(new.plan_id, index=999)
    with pytest.raises(Invalid, match="exactly one"):
        session.approve(new.plan_id)
    far = Pose.look_at(np.array([3.0, 0.0, 0.5]), np.zeros(3))
    with pytest.raises(Unreachable, match=r"beyond arm_reach|unreachable"):
        session.approve(new.plan_id, pose=far)
    inside = Pose.look_at(np.array([0.0, 0.0, 0.05]), np.array([0.3, 0.0, 0.05]))
    with pytest.raises(Unreachable):
        session.approve(new.plan_id, pose=inside)
    assert session.moves == 1 and session.state == State.PLANNED and session.pending is new


def test_an_override_is_recorded_as_one_with_the_planners_choice(registry: SessionRegistry) -> None:
    session = registry.create("mug", SMALL, seed=2)
    session.capture()
    entry = session.plan()
    other = next(i for i, s in enumerate(entry.plan.scores) if s.eligible and i != entry.plan.best_index)
    session.approve(entry.plan_id, index=other)
    decision = session.export()["decisions"][-1]
    assert decision["kind"] == str(DecisionKind.OVERRIDE)
    assert (decision["index"], decision["best_index"], decision["custom"]) == (other, entry.plan.best_index, False)
    assert session.record.iterations[-1]["decision"] == "override"


def test_a_device_fault_keeps_the_map_and_retry_redoes_the_step(registry: SessionRegistry) -> None:
    session = registry.create("l-block", SMALL, faults={"schedule": [{"kind": "capture_failure", "at": 2}]})
    session.capture()
    entry = session.plan()
    points = session.planner.cloud.shape[0]
    with pytest.raises(DeviceFault, match="map is unchanged"):
        session.approve(entry.plan_id, index=entry.plan.best_index)
    assert session.state == State.ERROR and session.planner.cloud.shape[0] == points
    assert session.pending is entry  # the failed approval's plan is pending again
    assert session.status()["retry"] == "approve"
    session.retry()
    assert session.state == State.READY and session.status()["iteration"] == 2
    kinds = [e["kind"] for e in session.export()["events"]]
    assert kinds == ["error", "retry"]


def test_the_record_and_the_journal_hold_the_same_events(registry: SessionRegistry) -> None:
    """One shape per fact: the export is derived from the journaled events, config changes and retries included."""
    session = registry.create("l-block", SMALL, faults={"schedule": [{"kind": "capture_failure", "at": 2}]})
    session.capture()
    entry = session.plan()
    with pytest.raises(DeviceFault):
        session.approve(entry.plan_id, index=entry.plan.best_index)
    session.retry()
    session.change_config({"termination": {"max_views": 4}})
    session.auto.step(1)
    assert session.journal is not None
    journal = read_journal(session.journal.directory)
    journaled = [e["kind"] for e in journal.events if e["kind"] not in ("capture", "plan", "decision")]
    exported = session.export()
    assert (
        [e["kind"] for e in exported["events"]]
        == journaled
        == [
            "error",
            "retry",
            "config",
        ]
    )
    assert len(exported["plans"]) == len(journal.of_kind("plan")) == 2
    assert len(exported["iterations"]) == len(journal.of_kind("capture")) == 3
    assert exported["config"]["termination"]["max_views"] == 4
    assert json.loads(json.dumps(exported)) == exported


def test_auto_mode_runs_in_the_background_and_stops_on_request(registry: SessionRegistry) -> None:
    session = registry.create("l-block", SMALL)
    session.capture()
    session.auto.start(3)
    with pytest.raises(Conflict, match="busy"):
        session.plan()
    assert wait_for_state(session, {"ready", "planned", "done"}) in ("ready", "done")
    assert session.auto.join(30)
    assert session.status()["iteration"] == 4
    assert [d["kind"] for d in session.export()["decisions"]] == ["auto"] * 3
    session.auto.start(50)
    assert session.auto.stop()
    assert session.auto.join(60)
    assert session.state in (State.READY, State.PLANNED) and session.status()["iteration"] <= 5


def test_only_the_planners_per_plan_sections_change_during_a_session(registry: SessionRegistry) -> None:
    session = registry.create("l-block", SMALL)
    with pytest.raises(Invalid, match="voxel cannot change"):
        session.change_config({"voxel": {"resolution": 0.03}})
    with pytest.raises(Invalid, match="config"):
        session.change_config({"partitions": {"sectors": 0}})
    assert session.change_config({"partitions": {"sectors": 6}})["partitions"]["sectors"] == 6


def test_an_interrupted_session_reports_the_same_status_shape(registry: SessionRegistry) -> None:
    session = registry.create("l-block", SMALL, seed=5)
    session.capture()
    live = session.status()
    assert session.journal is not None
    session.journal.close()  # the server "stops": a new registry on the same data lists it as interrupted
    other = SessionRegistry(registry.settings)
    dormant = other.status(session.id)
    assert set(dormant) == set(live)
    assert dormant["state"] == "interrupted" and dormant["iteration"] == live["iteration"] == 1
    assert (dormant["coverage"], dormant["points"], dormant["voxels"]) == (
        live["coverage"],
        live["points"],
        live["voxels"],
    )


def test_a_simulated_session_reports_its_reachable_ceiling(registry: SessionRegistry) -> None:
    """Asking for the metrics starts the ceiling's computation in a worker process; it arrives later, above
    the coverage a first view reaches, and is cached for the next session on the same object."""
    session = registry.create("l-block", SMALL)
    session.capture()
    assert session.metrics()["ceiling"] is None  # asked now, computed in the background
    ceiling = wait_until(lambda: session.metrics()["ceiling"], timeout=240, what="the ceiling")
    coverage = session.status()["coverage"]
    assert 0 < coverage < ceiling <= 1
    metrics = session.metrics()  # the ceiling-normalised metrics of the views so far
    assert metrics["coverage_ratio"] == [coverage / ceiling]
    assert metrics["auc"] == coverage / ceiling and metrics["views_to_90"] == (1 if coverage / ceiling >= 0.9 else 2)
    cached = list((registry.settings.data_dir / "ceilings").glob("*.json"))
    assert len(cached) == 1 and json.loads(cached[0].read_text())["coverage"] == ceiling


def test_a_discard_is_claimed_as_discarding_then_settles_with_its_plan_pending(registry: SessionRegistry) -> None:
    session = registry.create("l-block", SMALL, seed=1)
    session.capture()
    entry = session.plan()
    assert entry.plan.best_index is not None
    session.approve(entry.plan_id, index=entry.plan.best_index)
    seen: list[tuple[SessionEvent, State]] = []
    session.listeners.append(lambda s, event: seen.append((event, s.state)) if event != SessionEvent.PROGRESS else None)
    assert session.discard_last_view()["discarded"] == 2
    assert seen == [(SessionEvent.STATE, State.DISCARDING), (SessionEvent.CAPTURED, State.PLANNED)]
    assert session.status()["iteration"] == 1 and session.pending is not None
    assert session.pending.plan_id == entry.plan_id  # the plan whose approval took the discarded view
    session.discard_last_view()  # the first view too: the session is new again, as before its capture
    assert session.state == State.NEW and session.status()["iteration"] == 0
