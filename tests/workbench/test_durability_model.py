"""A model-based test of durability: random runs of sessions through the registry, with restarts (graceful and
abrupt), resumes, a full disk, sleep and wake at a live-session limit, a viewer that follows its sessions, creates
released together and reads in flight while sessions are put to sleep, against these invariants:

    every view the workbench acknowledged (its call returned) is in the journal and survives any later
    restart and any sleep and wake, and nothing it did not acknowledge appears;
    a viewer of a session (``SessionRegistry.follow``) hears every view it takes, across sleep and wake;
    never more than ``max_live_sessions`` are live, even when creates race;
    a valid request is never answered as invalid (422: Invalid) nor as a server failure (5xx: AtCapacity,
    Interrupted, and StorageFault or DeviceFault while the disk has room); a read in flight is not cut off.

The model is what the caller was told: per session, the poses of its acknowledged views in order (a
discard pops the last one), and which sessions exist. After every rule the journals on disk are checked
against it (captures without the discarded ones, each frame present with its sha256); after a restart and a
resume the session's record is checked against it too. ``benchmarks/soak_durability.py`` runs the same
machine with many more examples.
"""

from __future__ import annotations

import shutil
import tempfile
import threading
from collections.abc import Callable
from pathlib import Path
from typing import Any

import hypothesis.strategies as st
import pytest
from hypothesis import HealthCheck, Phase, settings
from hypothesis.stateful import RuleBasedStateMachine, initialize, invariant, precondition, rule

from devices.config import CameraConfig, DeviceConfig
from planner import PlannerConfig
from tests.full_disk import FullDisk
from tests.helpers import SMALL_SCORE_POINTS
from workbench.errors import (
    AtCapacity,
    Conflict,
    DeviceFault,
    Interrupted,
    Invalid,
    StorageFault,
    Unreachable,
    WorkbenchError,
)
from workbench.journal.discard import without_discarded
from workbench.journal.store import list_journals, read_journal, sessions_dir
from workbench.registry.registry import SessionRegistry
from workbench.session.session import Session
from workbench.session.values import SessionEvent
from workbench.settings import WorkbenchSettings

pytestmark = pytest.mark.slow  # tests/conftest.py: handed out with the long groups, first

TINY = {
    "voxel": {"resolution": 0.025},
    "candidates": {"count": 24, "parallels": 3},
    "cluster": {"t_min": 2, "t_max": 4},
}
"""A coarse map and few candidates: a capture or a plan takes a fraction of a second."""
CAMERA = CameraConfig(width=96, height=72, fx=92.0, fy=92.0, cx=48.0, cy=36.0)
"""A small depth image: fast rendering, small frames."""
MODELS = ("l-block", "mug")
LIMIT = 2
"""``max_live_sessions``: the runs create more, so sessions sleep and wake all the time."""


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
            max_live_sessions=LIMIT,
            idle_sleep=0.0,  # the rules put sessions to sleep
        )
        self.storage = FullDisk()
        self._patch = self.storage.installed()
        self._patch.__enter__()
        self.views: dict[str, list[tuple[float, ...]]] = {}
        """Session id -> the poses of its acknowledged views, in order."""
        self.live: set[str] = set()
        """Sessions a request reaches (live or asleep: a request wakes them), not interrupted by a restart."""
        self.heard: dict[str, list[SessionEvent]] = {}
        """Session id -> the events its viewer heard (``follow``), since the viewer was attached."""
        self.most_live = 0
        """The most sessions live at once, seen as each became live."""
        self.registry = self._new_registry()

    def _new_registry(self) -> SessionRegistry:
        registry = SessionRegistry(self.settings)
        registry.on_create.append(lambda _session: self._count_live(registry))
        return registry

    def _count_live(self, registry: SessionRegistry) -> None:
        self.most_live = max(self.most_live, len(registry.list()))

    def _follow(self, sid: str) -> None:
        """A viewer on ``sid`` (a tab's 3D view): it hears the session's events across its sleeps and wakes."""
        self.heard[sid] = []
        self.registry.follow(sid, lambda session, event: self.heard[session.id].append(event))

    def teardown(self) -> None:
        try:
            self.registry.close()
        finally:
            self._patch.__exit__(None, None, None)
            shutil.rmtree(self.root, ignore_errors=True)

    # ------------------------------------------------------------------ helpers

    def _acknowledge(self, sid: str, result: dict[str, Any]) -> None:
        self.views[sid].append(_pose_key(result["pose"]))

    def _heard_since(self, sid: str, mark: int, views: int) -> None:
        """The viewer heard (at least) one ``captured`` per view acknowledged since ``mark``."""
        heard = self.heard[sid][mark:].count(SessionEvent.CAPTURED)
        assert heard >= views, f"session {sid}: {views} views acknowledged, its viewer heard {heard}"

    def _try(self, action: Callable[[], Any]) -> Any:
        """The result of an action, or None when the workbench refused it (a refusal acknowledges nothing). A
        valid request is never refused as invalid (422) nor as a server failure (5xx), except the full disk's
        (StorageFault, and DeviceFault for a view it could not store)."""
        try:
            return action()
        except WorkbenchError as exc:
            disk_full = isinstance(exc, StorageFault | DeviceFault) and self.storage.full
            legit = isinstance(exc, Conflict | Unreachable) or disk_full
            assert legit or not isinstance(exc, Invalid | AtCapacity | Interrupted | StorageFault | DeviceFault), (
                f"a valid request refused with {type(exc).__name__}: {exc.detail}"
            )
            return None

    def _session(self, sid: str) -> Session | None:
        """The session a request for ``sid`` reaches (woken when it sleeps), None when refused."""
        session = self._try(lambda: self.registry.get(sid))
        if session is not None:
            self._count_live(self.registry)
        return session

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
            self._follow(session.id)

    @precondition(lambda self: self.live)
    @rule(data=st.data())
    def capture(self, data: st.DataObject) -> None:
        self._capture(data.draw(st.sampled_from(self.live_ids)))

    def _capture(self, sid: str) -> None:
        session = self._session(sid)
        if session is None:
            return
        mark = len(self.heard[sid])
        result = self._try(session.capture)
        if result is not None:
            self._acknowledge(sid, result)
            self._heard_since(sid, mark, 1)

    @precondition(lambda self: self.live)
    @rule(data=st.data())
    def plan(self, data: st.DataObject) -> None:
        sid = data.draw(st.sampled_from(self.live_ids))
        session = self._session(sid)
        if session is not None:
            self._try(session.plan)

    @precondition(lambda self: self.live)
    @rule(data=st.data())
    def approve(self, data: st.DataObject) -> None:
        sid = data.draw(st.sampled_from(self.live_ids))
        session = self._session(sid)
        pending = None if session is None else session.pending
        if session is None or pending is None:
            return
        mark = len(self.heard[sid])
        result = self._try(lambda: session.approve(pending.plan_id, index=pending.plan.best_index))
        if result is not None:
            self._acknowledge(sid, result)
            self._heard_since(sid, mark, 1)

    @precondition(lambda self: self.live)
    @rule(data=st.data(), count=st.integers(1, 2))
    def step(self, data: st.DataObject, count: int) -> None:
        self._step(data.draw(st.sampled_from(self.live_ids)), count)

    def _step(self, sid: str, count: int) -> None:
        session = self._session(sid)
        if session is None:
            return
        mark = len(self.heard[sid])
        results = self._try(lambda: session.auto.step(count))
        if results is None:  # a later step failed: the views before it are taken, and the status says so
            results = session.record.iterations[len(self.views[sid]) :]
        for result in results:
            self._acknowledge(sid, result)
        self._heard_since(sid, mark, len(results))

    @precondition(lambda self: self.live)
    @rule(data=st.data())
    def discard(self, data: st.DataObject) -> None:
        sid = data.draw(st.sampled_from(self.live_ids))
        session = self._session(sid)
        if session is not None and self._try(session.discard_last_view) is not None:
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
        session = self._session(data.draw(st.sampled_from(self.live_ids)))
        if session is not None:
            session.auto.stop()
            session.stop_plan()

    @rule()
    def restart_graceful(self) -> None:
        self.registry.close()
        self.registry = self._new_registry()
        self.live.clear()

    @rule()
    def restart_abrupt(self) -> None:
        """kill -9: nothing more is written; the OS closes the journals (every append was fsynced already)."""
        for session in self.registry.list():
            if session.journal is not None:
                session.journal.close()
        self.registry.ceilings.close()
        self.registry = self._new_registry()
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
        session = self._session(sid)
        if session is not None and self._try(session.discard_last_view) is not None:
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
        self._follow(sid)  # the tab that resumed it shows it
        assert rebuilt.dropped == [], rebuilt.dropped
        poses = [_pose_key(it["pose"]) for it in session.record.iterations]
        assert poses == self.views[sid], (
            f"session {sid}: resumed {len(poses)} views, {len(self.views[sid])} acknowledged"
        )
        assert session.planner.iteration == len(self.views[sid])

    @rule(full=st.booleans())
    def disk(self, full: bool) -> None:
        self.storage.full = full

    # ------------------------------------------------------------------ sleep, wake, races at the limit

    @precondition(lambda self: self.live)
    @rule(data=st.data())
    def sleep(self, data: st.DataObject) -> None:
        """The idle sweeper (or a create past the limit) puts a session to sleep: its journal is all it keeps."""
        self.registry.sleep(data.draw(st.sampled_from(self.live_ids)))

    @precondition(lambda self: self.live)
    @rule(data=st.data())
    def viewer_across_sleep_and_wake(self, data: st.DataObject) -> None:
        """A tab shows a session; the session sleeps, a request wakes it and takes a view: the tab hears it."""
        sid = data.draw(st.sampled_from(self.live_ids))
        self.registry.sleep(sid)
        self._step(sid, 1)

    @precondition(lambda self: self.live)
    @rule(data=st.data())
    def wake(self, data: st.DataObject) -> None:
        """A request for a session (asleep or not) reaches it as acknowledged: the same views."""
        sid = data.draw(st.sampled_from(self.live_ids))
        session = self._session(sid)
        if session is not None:
            poses = [_pose_key(it["pose"]) for it in session.record.iterations]
            assert poses == self.views[sid], (
                f"session {sid}: woke with {len(poses)} views, {len(self.views[sid])} acknowledged"
            )

    @rule(count=st.integers(2, 3), model=st.sampled_from(MODELS))
    def creates_together(self, count: int, model: str) -> None:
        """``count`` creates released at one instant at the limit: each is created (older sessions sleep to make
        room), and no more than the limit are live at any moment (the on_create hook counts them)."""
        barrier = threading.Barrier(count)
        made: list[Any] = []

        def create() -> None:
            barrier.wait()
            made.append(self._try(lambda: self.registry.create(model)))

        threads = [threading.Thread(target=create) for _ in range(count)]
        for thread in threads:
            thread.start()
        for thread in threads:
            thread.join(120)
        for session in made:
            if session is not None:
                self.views[session.id] = []
                self.live.add(session.id)
                self._follow(session.id)

    @precondition(lambda self: self.live)
    @rule(data=st.data(), model=st.sampled_from(MODELS))
    def read_while_sleeps_are_asked(self, data: st.DataObject, model: str) -> None:
        """A request in flight (a timeline read, held as a request holds its session) while the sweeper asks the
        session to sleep and a create at the limit needs room: the session is not put to sleep under the read,
        the read answers every acknowledged view, and the create is made once the read has ended."""
        sid = data.draw(st.sampled_from(self.live_ids))
        made: list[Any] = []
        creator = threading.Thread(target=lambda: made.append(self._try(lambda: self.registry.create(model))))
        held = self.registry.hold(sid)
        session = self._try(held.__enter__)  # woken if it slept, as for any request
        if session is None:
            return
        try:
            self._count_live(self.registry)
            assert not self.registry.sleep(sid), f"session {sid} was put to sleep under a request in flight"
            creator.start()
            steps = self._try(session.history.steps)
            if steps is not None:
                assert len(steps) == len(self.views[sid]), f"session {sid}: the read shows {len(steps)} views"
            assert sid in {s.id for s in self.registry.list()}, f"session {sid} slept under its read"
        finally:
            held.__exit__(None, None, None)
        creator.join(120)
        if made and made[0] is not None:
            self.views[made[0].id] = []
            self.live.add(made[0].id)
            self._follow(made[0].id)

    # ------------------------------------------------------------------ the invariant

    def _listed(self) -> set[str]:
        return {s["id"] for s in self.registry.list_status()}

    @invariant()
    def never_more_than_the_limit_live(self) -> None:
        live = len(self.registry.list())
        assert live <= LIMIT and self.most_live <= LIMIT, f"{live} live now, {self.most_live} at most; limit {LIMIT}"

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
    max_examples=12,
    stateful_step_count=18,
    deadline=None,
    suppress_health_check=[HealthCheck.too_slow, HealthCheck.filter_too_much],
    derandomize=True,
    phases=[Phase.explicit, Phase.reuse, Phase.generate],  # no shrinking in the suite: a failure reports at once
)
