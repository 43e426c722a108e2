"""A model-based test of durability (issue 21): random runs of sessions through the registry, with restarts
(graceful and abrupt), resumes and a full disk, against one invariant:

    every view the workbench acknowledged (its call returned) is in the journal and survives any later
    restart, and nothing it did not acknowledge appears.

The model is what the caller was told: per session, the poses of its acknowledged views in order (a
discard pops the last one), and which sessions exist. After every rule the journals on disk are checked
against it (captures without the discarded ones, each frame present with its sha256); after a restart and a
resume the session's record is checked against it too. ``benchmarks/soak_durability.py`` runs the same
machine with many more examples.
"""

from __future__ import annotations

import shutil
import tempfile
from collections.abc import Callable
from pathlib import Path
from typing import Any

import hypothesis.strategies as st
from hypothesis import HealthCheck, Phase, settings
from hypothesis.stateful import RuleBasedStateMachine, initialize, invariant, precondition, rule

from devices.config import CameraConfig, DeviceConfig
from planner import PlannerConfig
from tests.full_disk import FullDisk
from tests.helpers import SMALL_SCORE_POINTS
from workbench.errors import WorkbenchError
from workbench.journal.discard import without_discarded
from workbench.journal.store import list_journals, read_journal, sessions_dir
from workbench.registry.registry import SessionRegistry
from workbench.settings import WorkbenchSettings

TINY = {
    "voxel": {"resolution": 0.025},
    "candidates": {"count": 24, "parallels": 3},
    "cluster": {"t_min": 2, "t_max": 4},
}
"""A coarse map and few candidates: a capture or a plan takes a fraction of a second."""
CAMERA = CameraConfig(width=96, height=72, fx=92.0, fy=92.0, cx=48.0, cy=36.0)
"""A small depth image: fast rendering, small frames."""
MODELS = ("l-block", "mug")


def _pose_key(pose: dict[str, Any]) -> tuple[float, ...]:
    """A view's pose (``Pose.to_dict``) as a comparable key."""
    return tuple(round(float(v), 9) for v in [*pose["position"], *pose["wxyz"]])


class Durability(RuleBasedStateMachine):
    """Sessions of one data directory, driven through the registry; the model is what was acknowledged."""

    def __init__(self) -> None:
        super().__init__()
        self.root = Path(tempfile.mkdtemp(prefix="nbv-durability-"))
        self.settings = WorkbenchSettings(
            models_dir=self.root / "models",
            data_dir=self.root / "data",
            workers=False,
            planner=PlannerConfig().replace(**TINY),
            devices=DeviceConfig(camera=CAMERA),
            surface_score_points=SMALL_SCORE_POINTS,  # what is checked is what survives, not the scores
        )
        self.storage = FullDisk()
        self._patch = self.storage.installed()
        self._patch.__enter__()
        self.registry = SessionRegistry(self.settings)
        self.views: dict[str, list[tuple[float, ...]]] = {}
        """Session id -> the poses of its acknowledged views, in order."""
        self.live: set[str] = set()

    def teardown(self) -> None:
        try:
            self.registry.close()
        finally:
            self._patch.__exit__(None, None, None)
            shutil.rmtree(self.root, ignore_errors=True)

    # ------------------------------------------------------------------ helpers

    def _acknowledge(self, sid: str, result: dict[str, Any]) -> None:
        self.views[sid].append(_pose_key(result["pose"]))

    def _try(self, action: Callable[[], Any]) -> Any:
        """The result of an action, or None when the workbench refused it (a refusal acknowledges nothing)."""
        try:
            return action()
        except WorkbenchError:
            return None

    def _journal_views(self, directory: Path) -> list[tuple[float, ...]]:
        journal = read_journal(directory)
        captures = [e for e in without_discarded(journal.events) if e["kind"] == "capture"]
        poses = []
        for event in captures:
            assert event.get("frame") is not None, f"capture {event['iteration']} journaled without its frame"
            assert (directory / event["frame"]).is_file(), f"frame {event['frame']} is missing"
            journal.frame(event)  # the frame reads back with its sha256
            poses.append(_pose_key(event.get("pose_used", event["pose"])))  # as the record reads it
        return poses

    @property
    def live_ids(self) -> list[str]:
        """Live sessions in the order they were created (ids are random: sorting them would make draws flaky)."""
        return [sid for sid in self.views if sid in self.live]

    @property
    def dormant_ids(self) -> list[str]:
        return [sid for sid in self.views if sid not in self.live]

    # ------------------------------------------------------------------ rules

    @initialize(model=st.sampled_from(MODELS))
    def a_scan_under_way(self, model: str) -> None:
        """Every run starts from a session with one view (the runs that matter are about what follows)."""
        self.create(model, 0)
        self._capture(self.live_ids[0])

    @rule(model=st.sampled_from(MODELS), seed=st.integers(0, 3))
    def create(self, model: str, seed: int) -> None:
        session = self._try(lambda: self.registry.create(model, seed=seed))
        if session is not None:
            self.views[session.id] = []
            self.live.add(session.id)

    @precondition(lambda self: self.live)
    @rule(data=st.data())
    def capture(self, data: st.DataObject) -> None:
        self._capture(data.draw(st.sampled_from(self.live_ids)))

    def _capture(self, sid: str) -> None:
        result = self._try(self.registry.get(sid).capture)
        if result is not None:
            self._acknowledge(sid, result)

    @precondition(lambda self: self.live)
    @rule(data=st.data())
    def plan(self, data: st.DataObject) -> None:
        sid = data.draw(st.sampled_from(self.live_ids))
        self._try(self.registry.get(sid).plan)

    @precondition(lambda self: self.live)
    @rule(data=st.data())
    def approve(self, data: st.DataObject) -> None:
        sid = data.draw(st.sampled_from(self.live_ids))
        session = self.registry.get(sid)
        pending = session.pending
        if pending is None:
            return
        result = self._try(lambda: session.approve(pending.plan_id, index=pending.plan.best_index))
        if result is not None:
            self._acknowledge(sid, result)

    @precondition(lambda self: self.live)
    @rule(data=st.data(), count=st.integers(1, 2))
    def step(self, data: st.DataObject, count: int) -> None:
        sid = data.draw(st.sampled_from(self.live_ids))
        session = self.registry.get(sid)
        results = self._try(lambda: session.auto.step(count))
        if results is None:  # a later step failed: the views before it are taken, and the status says so
            results = session.record.iterations[len(self.views[sid]) :]
        for result in results:
            self._acknowledge(sid, result)

    @precondition(lambda self: self.live)
    @rule(data=st.data())
    def discard(self, data: st.DataObject) -> None:
        sid = data.draw(st.sampled_from(self.live_ids))
        if self._try(self.registry.get(sid).discard_last_view) is not None:
            self.views[sid].pop()

    @precondition(lambda self: self.views)
    @rule(data=st.data())
    def delete(self, data: st.DataObject) -> None:
        sid = data.draw(st.sampled_from(list(self.views)))
        if self._try(lambda: self.registry.delete(sid)) is not None or sid not in self._listed():
            self.views.pop(sid)
            self.live.discard(sid)

    @precondition(lambda self: self.live)
    @rule(data=st.data())
    def stop(self, data: st.DataObject) -> None:
        """Stop a session's auto mode or plan (nothing runs in the background here: it must change nothing)."""
        session = self.registry.get(data.draw(st.sampled_from(self.live_ids)))
        session.auto.stop()
        session.stop_plan()

    @rule()
    def restart_graceful(self) -> None:
        self.registry.close()
        self.registry = SessionRegistry(self.settings)
        self.live.clear()

    @rule()
    def restart_abrupt(self) -> None:
        """kill -9: nothing more is written; the OS closes the journals (every append was fsynced already)."""
        for session in self.registry.list():
            if session.journal is not None:
                session.journal.close()
        self.registry.ceilings.close()
        self.registry = SessionRegistry(self.settings)
        self.live.clear()

    @rule(abrupt=st.booleans())
    def restart_and_resume_all(self, abrupt: bool) -> None:
        """A restart after which the person resumes every session (what the page's Resume button does)."""
        self.restart_abrupt() if abrupt else self.restart_graceful()
        for sid in self.dormant_ids:
            self._resume(sid)

    @precondition(lambda self: any(self.views[sid] for sid in self.live))
    @rule(data=st.data(), abrupt=st.booleans())
    def discard_then_restart_twice(self, data: st.DataObject, abrupt: bool) -> None:
        """A discard, then two restarts each followed by a resume of every session: what a resume writes must keep
        the discard (a resume once cut it off the journal, and the discarded view was back after the next restart)."""
        sid = data.draw(st.sampled_from([sid for sid in self.live_ids if self.views[sid]]))
        if self._try(self.registry.get(sid).discard_last_view) is not None:
            self.views[sid].pop()
        self.restart_and_resume_all(abrupt)
        self.restart_and_resume_all(abrupt)

    @precondition(lambda self: set(self.views) - self.live)
    @rule(data=st.data())
    def resume(self, data: st.DataObject) -> None:
        self._resume(data.draw(st.sampled_from(self.dormant_ids)))

    def _resume(self, sid: str) -> None:
        resumed = self._try(lambda: self.registry.resume(sid))
        if resumed is None:
            return
        session, rebuilt = resumed
        self.live.add(sid)
        assert rebuilt.dropped == [], rebuilt.dropped
        poses = [_pose_key(it["pose"]) for it in session.record.iterations]
        assert poses == self.views[sid], (
            f"session {sid}: resumed {len(poses)} views, {len(self.views[sid])} acknowledged"
        )
        assert session.planner.iteration == len(self.views[sid])

    @rule(full=st.booleans())
    def disk(self, full: bool) -> None:
        self.storage.full = full

    # ------------------------------------------------------------------ the invariant

    def _listed(self) -> set[str]:
        return {s["id"] for s in self.registry.list_status()}

    @invariant()
    def acknowledged_views_are_journaled(self) -> None:
        journals = {d.name: d for d in list_journals(self.settings.data_dir)}
        listed = self._listed()
        assert listed == set(self.views), f"listed {sorted(listed)}, acknowledged {sorted(self.views)}"
        assert {s["id"] for s in self.registry.list_status() if s["state"] == "damaged"} == set()
        for sid, poses in self.views.items():
            assert sid in journals, f"session {sid}: no journal"
            journaled = self._journal_views(journals[sid])
            assert journaled == poses, f"session {sid}: {len(journaled)} views journaled, {len(poses)} acknowledged"
        for directory in (sessions_dir(self.settings.data_dir)).glob("*/frames/.*.part"):
            raise AssertionError(f"{directory} left behind")


TestDurability = Durability.TestCase
TestDurability.settings = settings(
    max_examples=8,
    stateful_step_count=14,
    deadline=None,
    suppress_health_check=[HealthCheck.too_slow, HealthCheck.filter_too_much],
    derandomize=True,
    phases=[Phase.explicit, Phase.reuse, Phase.generate],  # no shrinking in the suite: a failure reports at once
)
