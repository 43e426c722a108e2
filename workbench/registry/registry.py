"""The registry of sessions: live ones (a Session each, with its own lock) and journaled ones from an earlier
server process, listed as ``interrupted`` until ``resume`` rebuilds them. The registry's lock guards only its dicts."""

from __future__ import annotations

import contextlib
import dataclasses
import logging
import secrets
import threading
import time
from collections.abc import Callable, Iterator
from pathlib import Path
from typing import Any

from devices.config import DeviceConfig
from devices.faults import FaultConfig
from devices.planner_noise import planner_config_for
from planner import PlannerConfig
from planner.config import from_dict
from planner.evaluators import evaluator_names
from workbench.errors import AtCapacity, Conflict, Interrupted, Invalid, NotFound, StorageFault
from workbench.evaluation.ceiling_service import CeilingService
from workbench.journal.rebuild import REPLAY_STAGE, Rebuilt
from workbench.journal.store import JournalBusyError, JournalWriter, in_use, list_journals, read_journal, sessions_dir
from workbench.journal.trash import move_to_trash, prune
from workbench.registry.creations import Creation, Creations, resume_id
from workbench.registry.dormant import DormantSession, read_dormant, unreadable
from workbench.registry.idle import IdleSweeper
from workbench.session.session import Session
from workbench.session.states import BUSY
from workbench.session.values import SessionEvent
from workbench.settings import WorkbenchSettings
from workbench.sources.camera_models import check_camera_models
from workbench.sources.limits import check_config
from workbench.sources.parts import SURFACE_SAMPLES, SessionParts, build_parts, check_arm_name, session_devices
from workbench.workers.client import JobKilled, offload_rendering, render_spec, truth_spec
from workbench.workers.pool import Engine

__all__ = ["SURFACE_SAMPLES", "DormantSession", "SessionRegistry"]
log = logging.getLogger(__name__)

ROOM_WAIT = 60.0
"""Seconds a create or wake at ``max_live_sessions`` waits for the creates and wakes ahead of it to finish (their
sessions may then sleep to make room) before it is refused (AtCapacity)."""
HOLD_TRIES = 5
"""How often :meth:`SessionRegistry.hold` wakes a session that went back to sleep before it could hold it."""


@dataclasses.dataclass(eq=False)
class _Slot:
    """One live session's place under ``max_live_sessions``, reserved by a create or a wake before its session
    exists; handed to the session when it is registered (``used``), else given back."""

    used: bool = False


def _release(parts: SessionParts) -> None:
    """Close the devices of parts no session took (a hardware cell holds its devices until closed)."""
    parts.cell.close()


class SessionRegistry:
    """Creates, finds, resumes and deletes sessions. ``on_create`` / ``on_delete`` hooks let the scene follow."""

    def __init__(self, settings: WorkbenchSettings) -> None:
        self.settings = settings
        self._lock = threading.Lock()
        self._sessions: dict[str, Session] = {}
        self._dormant: dict[str, DormantSession] = {}
        self._resuming: set[str] = set()
        self._rebuilding: dict[str, DormantSession] = {}
        """Interrupted sessions being resumed now: still listed (as interrupted) until they are live."""
        self._used: dict[str, float] = {}
        """Live session id -> when a request last asked for it (time.monotonic): who sleeps first."""
        self._waking: dict[str, threading.Lock] = {}
        self._changed = threading.Condition(self._lock)
        """Notified when a slot is given back or handed to its session, a hold ends or a sleep ends."""
        self._reserved = 0
        """Slots reserved by creates and wakes in flight (counted as live: the limit holds under races)."""
        self._holds: dict[str, int] = {}
        """Live session id -> requests and jobs holding it now (:meth:`hold`): it does not sleep meanwhile."""
        self._closing: set[str] = set()
        """Live sessions being put to sleep now: a hold waits for the sleep to end, then wakes them."""
        self._followers: dict[str, list[Callable[[Session, SessionEvent], None]]] = {}
        """Session id -> listeners that follow it across sleep and wake (:meth:`follow`)."""
        self.class_seats = 0
        """Seats of the server's classes (workbench/classes): the live limit holds at least this many sessions."""
        self.on_create: list[Callable[[Session], None]] = []
        self.on_delete: list[Callable[[Session], None]] = []
        self.ceilings = CeilingService(settings.data_dir / "ceilings")
        self.creations = Creations()
        """Creates in flight that a page follows (``progress_id``) and may cancel."""
        self.engine = (
            Engine(settings.max_running_jobs, settings.max_idle_workers)
            if getattr(settings, "workers", False)
            else None
        )
        """The sessions' worker processes (workbench/workers/pool.py); None: heavy work runs in this process."""
        if settings.journal:
            for directory in list_journals(settings.data_dir):
                if in_use(directory):  # live in another server on the same data directory
                    continue
                try:
                    dormant = read_dormant(directory)
                except (ValueError, KeyError, TypeError) as exc:
                    log.warning("journal %s is damaged: %s", directory, exc)
                    dormant = unreadable(directory, str(exc))
                if dormant is not None:
                    self._dormant[dormant.id] = dormant
                else:  # deleted by an earlier server that kept deleted journals in place
                    self._trash(directory)
            with contextlib.suppress(OSError):  # deleted in an earlier run: kept in the trash until this restart
                prune(settings.data_dir, 0, settings.trash_max_age)
        self._sweeper = (
            IdleSweeper(self.sleep_idle, min(30.0, settings.idle_sleep / 4))
            if settings.journal and settings.idle_sleep > 0
            else None
        )

    # ------------------------------------------------------------------ create

    def planner_config(self, overrides: dict[str, Any] | None, seed: int) -> PlannerConfig:
        """The default planner config with ``overrides`` (any subset); the seed goes to ``cluster.seed``
        unless the overrides set it. Invalid for unknown names, values out of range or beyond
        the API's bounds (app/limits.py)."""
        overrides = dict(overrides or {})
        cluster = overrides.get("cluster") or {}
        if isinstance(cluster, dict):
            overrides["cluster"] = {"seed": seed, **cluster}
        try:
            config = self.settings.planner.replace(**overrides)
        except (ValueError, TypeError) as exc:
            raise Invalid(f"config: {exc}") from None
        check_config(config, self.settings.max_session_voxels, self.settings.max_live_sessions)
        return config

    def _new_id(self) -> str:
        """A fresh id, unused by live, journaled and on-disk sessions (caller holds the lock)."""
        while True:
            sid = secrets.token_hex(4)
            taken = sid in self._sessions or sid in self._dormant or sid in self._resuming
            if not taken and not (sessions_dir(self.settings.data_dir) / sid).exists():
                return sid

    def create(
        self,
        model: str | None = None,
        config: dict[str, Any] | None = None,
        seed: int = 0,
        source: dict[str, Any] | None = None,
        faults: dict[str, Any] | None = None,
        planner: str = "projection",
        progress_id: str | None = None,
        camera: dict[str, Any] | None = None,
        guided: bool = False,
        arm: str | None = None,
        move_capture: float | None = None,
    ) -> Session:
        """A new session. 422 for a bad config, model, source, fault setting, planner or camera model; 404 for an
        unknown recording.

        planner: the view evaluator (``planner.evaluators.evaluator_names()``), journaled in the header.
        camera: ``{"sensor": NAME, "calibration": NAME}`` (either optional; default the server's
        ``devices.camera``): the simulated sensor and calibration error (``workbench.sources.camera_models``).
        arm: an arm preset or 'reach_sphere' (``workbench.sources.parts.arm_choices``; default the server's ``devices.cell``), recorded
        with the devices in the journal header (a journal without it resumes with the UR5).
        The planner config follows the camera (``devices.planner_noise.planner_config_for``) and the journal
        header records both, so a resume rebuilds the same map.
        progress_id: names this create for its progress and its cancellation (:attr:`creations`); cancelled,
        it raises Conflict at its next stage and leaves nothing.
        guided: the page explains each step (journaled in the header, so a resume keeps it; the status's ``guided``).
        """
        planner_config = self.planner_config(config, seed)
        if planner not in evaluator_names():
            raise Invalid(f"planner: unknown {planner!r} (known: {', '.join(evaluator_names())})")
        try:
            fault_config = self.settings.faults if faults is None else FaultConfig.from_dict(faults)
        except ValueError as exc:
            raise Invalid(str(exc)) from None
        if progress_id is not None and progress_id.startswith(resume_id("")):
            raise Invalid(f"progress_id: {progress_id!r} starts with 'resume-', which resumes use")
        camera_models = check_camera_models(camera)
        arm = check_arm_name(arm)
        if move_capture is not None and (
            isinstance(move_capture, bool) or not (isinstance(move_capture, int | float) and 0 <= move_capture <= 60)
        ):
            raise Invalid(f"move_capture: frames per second in [0, 60], got {move_capture!r}")
        slot = self._make_room()
        try:
            with self.creations.run(progress_id) as creation:
                return self._create(
                    planner_config,
                    model,
                    seed,
                    source,
                    fault_config,
                    faults is not None,
                    planner,
                    creation,
                    camera_models,
                    slot,
                    guided,
                    arm,
                    move_capture,
                )
        finally:
            self._give_back(slot)

    def _create(
        self,
        planner_config: PlannerConfig,
        model: str | None,
        seed: int,
        source: dict[str, Any] | None,
        fault_config: FaultConfig,
        faults_asked: bool,
        planner: str,
        creation: Creation,
        camera: dict[str, str] | None = None,
        slot: _Slot | None = None,
        guided: bool = False,
        arm: str | None = None,
        move_capture: float | None = None,
    ) -> Session:
        name = model or self.settings.devices.model
        devices = session_devices(self.settings, name, seed, camera, arm, move_capture)
        parts = build_parts(
            self.settings, name, source, seed, devices, fault_config, creation.stage, faults_asked, bool(camera)
        )
        if parts.injector is None:
            fault_config = FaultConfig()  # real hardware: none injected (the journal says so)
            # nor the server's simulated sensor: the planner assumes the noise the cell file names for its camera
            camera = {"sensor": parts.noise_model, "calibration": "none"}
        try:
            creation.stage("starting the session")
        except Conflict:
            _release(parts)
            raise
        devices = session_devices(self.settings, parts.model, seed, camera, arm, move_capture)
        planner_config = planner_config_for(planner_config, devices.camera)  # also what the header records
        with self._lock:
            session_id = self._new_id()
            self._resuming.add(session_id)  # reserved while the journal is created outside the lock
        session = None
        try:
            journal = None
            if self.settings.journal:
                header = {
                    "model": {"name": parts.model, "kind": parts.model_kind},
                    "source": parts.source,
                    "config": planner_config.to_dict(),
                    "seed": seed,
                    "planner": planner,
                    "devices": dataclasses.asdict(devices),
                    "faults": fault_config.to_dict(),
                    "guided": guided,
                }
                try:
                    journal = JournalWriter.create(self.settings.data_dir, session_id, header)
                except OSError as exc:
                    raise StorageFault(f"cannot journal the session in the data directory ({exc.strerror})") from None
            session = self._session(session_id, parts, planner_config, devices, seed, journal, planner)
            session.record.guided = guided
            with self._lock:
                self._register(session_id, session, slot)
        except BaseException:
            if session is None:
                _release(parts)
            raise
        finally:
            with self._lock:
                self._resuming.discard(session_id)
        for hook in list(self.on_create):
            hook(session)
        return session

    def _session(
        self,
        sid: str,
        parts: SessionParts,
        config: PlannerConfig,
        devices: DeviceConfig,
        seed: int,
        journal: Any,
        evaluator: str = "projection",
    ) -> Session:
        s = self.settings
        worker = None
        if self.engine is not None:
            worker = self.engine.worker(sid, render_spec(parts.cell, devices.cell))
            worker.truth = truth_spec(parts.mesh, parts.surface_samples, s.surface_score_points)
            worker.warm = (parts.cell.config, parts.cell.joint_positions(), parts.cell.angle, config)
            offload_rendering(parts.cell, worker, s.capture_budget)
            worker.start_soon()  # and warm its planning cell while the person looks at the page and captures
        session = Session(
            sid,
            parts,
            config,
            devices,
            seed,
            journal=journal,
            capture_timeout=s.capture_timeout,
            move_timeout=s.move_timeout,
            evaluator=evaluator,
            worker=worker,
            plan_budget=s.plan_budget,
            capture_budget=s.capture_budget,
            surface_points=s.surface_score_points,
        )
        if parts.surface_samples is not None and parts.model_kind not in (
            "replay",
            "recorded",
        ):  # a ground truth in the sim cell

            def request() -> None:
                def done(value: float) -> None:
                    session.ceiling = value
                    session.notify(SessionEvent.STATE)

                self.ceilings.request(sid, parts.mesh, devices, config, done)

            session.request_ceiling = request
        return session

    # ------------------------------------------------------------------ find

    def get(self, session_id: str) -> Session:
        """The live session (a sleeping one is woken first); 409 for an interrupted one (resume it first), 404
        for an unknown id."""
        with self._lock:
            session = self._sessions.get(session_id)
            if session is not None:
                self._used[session_id] = time.monotonic()
            waking = self._dormant.get(session_id) or self._rebuilding.get(session_id)
            asleep = session is None and waking is not None and waking.asleep  # (being woken: wait for the waker)
            dormant = session_id in self._dormant
            rebuilding = session_id in self._rebuilding
        if asleep:
            return self.wake(session_id)
        if session is None:
            if rebuilding:
                raise Conflict(f"session {session_id!r} is being resumed; it is live in a moment")
            if dormant:
                raise Conflict(f"session {session_id!r} was interrupted (the server stopped); resume it first")
            raise NotFound(f"session {session_id!r}: unknown")
        return session

    def status(self, session_id: str) -> dict[str, Any]:
        """A session's status. A sleeping session wakes for the tab that opens it; when it cannot wake now (every
        live session busy, or it is being put to sleep or woken by another request) its status comes from its
        journal: a status read never fails because the session sleeps."""
        with self._lock:
            dormant = self._dormant.get(session_id) or self._rebuilding.get(session_id)
        if dormant is not None and not dormant.asleep:
            return dormant.status()
        try:
            return self.get(session_id).status()
        except (AtCapacity, Conflict, Interrupted, StorageFault):
            with self._lock:
                dormant = self._dormant.get(session_id) or self._rebuilding.get(session_id)
                session = self._sessions.get(session_id)
            if session is not None:
                return session.status()
            if dormant is None:
                raise
            return dormant.status()

    @contextlib.contextmanager
    def hold(self, session_id: str) -> Iterator[Session]:
        """The live session (woken when it sleeps), kept live while the ``with`` block runs: neither the idle
        sweeper nor a create past the limit puts it to sleep meanwhile, so a request or a job in flight (a
        timeline rebuild, a recording, a step) is never cut off by a sleep. Errors as :meth:`get`."""
        session = None
        for _ in range(HOLD_TRIES):
            with self._lock:
                while session_id in self._closing:  # being put to sleep now: wake it once it sleeps
                    self._changed.wait(1.0)
                live = self._sessions.get(session_id)
                if live is not None:
                    self._holds[session_id] = self._holds.get(session_id, 0) + 1
                    self._used[session_id] = time.monotonic()
                    session = live
                    break
            self.get(session_id)  # wakes it (or raises); another request may put it to sleep again: try again
        if session is None:
            raise AtCapacity(
                f"session {session_id!r} was put back to sleep {HOLD_TRIES} times before this request could use "
                "it (the server is at server.max_live_sessions); retry"
            )
        try:
            yield session
        finally:
            with self._lock:
                left = self._holds.get(session_id, 1) - 1
                if left > 0:
                    self._holds[session_id] = left
                else:
                    self._holds.pop(session_id, None)
                if session_id in self._used:
                    self._used[session_id] = time.monotonic()  # idle from the end of its last request
                self._changed.notify_all()

    def peek(self, session_id: str) -> tuple[Session | None, dict[str, Any]]:
        """(the live session or None, its status) without waking it: a board that watches many sessions must not
        keep them all awake. NotFound for an unknown id."""
        with self._lock:
            session = self._sessions.get(session_id)
            dormant = self._dormant.get(session_id) or self._rebuilding.get(session_id)
        if session is not None:
            return session, session.status()
        if dormant is not None:
            return None, dormant.status()
        raise NotFound(f"session {session_id!r}: unknown")

    def list(self) -> list[Session]:
        with self._lock:
            return list(self._sessions.values())

    def list_status(self) -> list[dict[str, Any]]:
        """Interrupted sessions (oldest first), then live ones."""
        with self._lock:
            dormant = sorted([*self._dormant.values(), *self._rebuilding.values()], key=lambda d: d.stopped)
            live = list(self._sessions.values())
        return [d.status() for d in dormant] + [session.status() for session in live]

    # ------------------------------------------------------------------ resume

    def resume(self, session_id: str) -> tuple[Session, Rebuilt]:
        """Rebuild an interrupted session from its journal: same frames, same config, same seed -> same map
        and same next plan. Fault injection is not re-armed. 404 unknown, 409 live or resuming, 422 damaged,
        503 (AtCapacity) when ``max_live_sessions`` are live and busy."""
        with self._lock:
            known = session_id in self._dormant
        slot = self._make_room() if known else None
        try:
            return self._resume(session_id, slot)
        finally:
            self._give_back(slot)

    def _resume(self, session_id: str, slot: _Slot | None) -> tuple[Session, Rebuilt]:
        with self._lock:
            dormant = self._dormant.get(session_id)
            if dormant is None:
                if session_id in self._rebuilding:
                    raise Conflict(f"session {session_id!r} is being resumed already")
                if session_id in self._sessions or session_id in self._resuming:
                    raise Conflict(f"session {session_id!r} is live; nothing to resume")
                raise NotFound(f"session {session_id!r}: unknown")
            del self._dormant[session_id]
            self._resuming.add(session_id)
            self._rebuilding[session_id] = dormant  # still listed while it is rebuilt
        try:
            with self.creations.run(resume_id(session_id), "resume", [REPLAY_STAGE], stoppable=False) as creation:
                session, rebuilt = self._rebuild(dormant, creation.tracker.stage)
        except BaseException:
            with self._lock:
                self._dormant[session_id] = dormant
                self._resuming.discard(session_id)
                del self._rebuilding[session_id]
            raise
        with self._lock:  # live and no longer rebuilding in one step: never unknown in between
            self._register(session_id, session, slot)
            self._resuming.discard(session_id)
            del self._rebuilding[session_id]
        for hook in list(self.on_create):
            hook(session)
        return session, rebuilt

    def _rebuild(
        self, dormant: DormantSession, progress: Callable[[str, int, int], None] | None = None
    ) -> tuple[Session, Rebuilt]:
        try:
            journal = read_journal(dormant.directory)
            header = journal.header
            devices = from_dict(DeviceConfig, header["devices"])
            config = PlannerConfig.from_journal(header["config"])
            seed = int(header["seed"])
        except (ValueError, KeyError, TypeError) as exc:
            raise Invalid(f"session {dormant.id}: cannot resume: {exc}") from None
        parts = build_parts(self.settings, header["model"]["name"], header.get("source"), seed, devices, FaultConfig())
        try:
            writer = JournalWriter.reopen(journal)  # first: it locks the journal against a second resumer
        except JournalBusyError as exc:
            _release(parts)
            raise Conflict(str(exc)) from None
        planner = str(header.get("planner", "projection"))
        session = self._session(dormant.id, parts, config, devices, seed, writer, planner)  # journaled from the start
        try:
            rebuilt = session.replay(journal, progress)
        except (ValueError, KeyError, TypeError, JobKilled) as exc:
            writer.close()
            if session.worker is not None:
                session.worker.close()
            _release(parts)
            if isinstance(exc, JobKilled):  # cut off (shutdown, a dead worker): the journal is fine, ask again
                raise Interrupted(f"session {dormant.id}: its resume was cut off: {exc}") from None
            raise Invalid(f"session {dormant.id}: cannot resume: {exc}") from None
        if rebuilt.kept < len(journal.events):  # a damaged event or frame: the journal goes on from before it
            journal.cut(rebuilt.kept)
            writer.cut_to(journal)
        session.restore(rebuilt)
        try:
            writer.append(
                "resume",
                verified=not rebuilt.mismatches,
                mismatches=rebuilt.mismatches,
                interrupted=rebuilt.interrupted,
                dropped=rebuilt.dropped,
            )
        except OSError as exc:  # a full disk: it stays interrupted (nothing it did could be journaled)
            session.close()
            raise StorageFault(f"session {dormant.id}: cannot resume: {exc.strerror or exc}") from None
        if rebuilt.dropped:
            log.warning("session %s resumed up to the damage; dropped: %s", dormant.id, "; ".join(rebuilt.dropped))
        if rebuilt.mismatches:
            log.warning("session %s resumed with differences: %s", dormant.id, "; ".join(rebuilt.mismatches))
        return session, rebuilt

    # ------------------------------------------------------------------ sleep and wake

    def wake(self, session_id: str) -> Session:
        """A sleeping session resumed from its journal (one waker at a time; the others wait for it)."""
        with self._lock:
            gate = self._waking.setdefault(session_id, threading.Lock())
        with gate:
            with self._lock:
                session = self._sessions.get(session_id)
            if session is not None:  # another request woke it meanwhile
                return session
            try:
                session, _ = self.resume(session_id)
            finally:
                with self._lock:
                    self._waking.pop(session_id, None)
            log.info("session %s woke up", session_id)
            return session

    def sleep(self, session_id: str) -> bool:
        """Put a live, idle, journaled session to sleep: closed (its worker and memory freed), listed from its
        journal, woken by the next request for it. False when it is busy, unjournaled or not live."""
        with self._lock:
            session = self._sessions.get(session_id)
            if session is None or session.journal is None:
                return False
            if self._holds.get(session_id) or session_id in self._closing:  # a request or job holds it
                return False
            self._closing.add(session_id)  # a hold from now on waits for the sleep, then wakes it
        dormant = None
        try:
            if not session.close_state():  # fenced: an action that gets the object now is refused (state closed)
                return False
            directory = session.journal.directory
            session.close()
            try:
                dormant = read_dormant(directory)
            except (ValueError, KeyError, TypeError) as exc:
                dormant = unreadable(directory, str(exc))
            with self._lock:
                if self._sessions.get(session_id) is session:
                    del self._sessions[session_id]
                    self._used.pop(session_id, None)
                    if dormant is not None:  # else deleted meanwhile: nothing to list
                        dormant.asleep = True
                        self._dormant[session_id] = dormant
        finally:
            with self._lock:
                self._closing.discard(session_id)
                self._changed.notify_all()
        if dormant is None:
            return False
        log.info("session %s put to sleep", session_id)
        return True

    def doze(self, session_id: str) -> bool:
        """Count a session of an earlier server process as asleep, not interrupted: the next request for it wakes it
        (a class's seats after a restart: a student's tab goes on without a resume). False when it is not such a
        session, or its journal is damaged (that one waits for an explicit resume)."""
        with self._lock:
            dormant = self._dormant.get(session_id)
            if dormant is None or dormant.damage is not None:
                return False
            dormant.asleep = True
            return True

    def sleep_idle(self) -> None:
        """Put every session idle for longer than ``idle_sleep`` seconds to sleep (the sweeper's job)."""
        limit = time.monotonic() - self.settings.idle_sleep
        with self._lock:
            idle = [sid for sid, used in self._used.items() if used < limit]
        for sid in idle:
            self.sleep(sid)

    def _make_room(self) -> _Slot:
        """A reserved slot for one more live session under ``max_live_sessions`` (the caller hands it to its
        session, :meth:`_hand_over`, or gives it back, :meth:`_give_back`). The least recently used idle sessions
        sleep to make room; slots reserved by creates and wakes in flight count as live, so concurrent creates
        never pass the limit. When none can sleep but creates or wakes are in flight, it waits for them (up to
        ``ROOM_WAIT`` s: their sessions may then sleep). AtCapacity when every live session is busy or held."""
        limit = self.live_limit()
        deadline = time.monotonic() + ROOM_WAIT
        while True:
            with self._lock:
                live = len(self._sessions) + self._reserved
                if limit <= 0 or live < limit:
                    self._reserved += 1
                    return _Slot()
                order = sorted(
                    (sid for sid in self._sessions if not self._holds.get(sid) and sid not in self._closing),
                    key=lambda sid: self._used.get(sid, 0.0),
                )
            if any(self.sleep(sid) for sid in order):
                continue
            with self._lock:
                # creates and wakes in flight, sleeps under way, and reads holding an idle session end soon
                held = any(self._holds.get(sid) and live.state not in BUSY for sid, live in self._sessions.items())
                pending = self._reserved > 0 or bool(self._closing) or held
                if pending and time.monotonic() < deadline and len(self._sessions) + self._reserved >= limit:
                    self._changed.wait(min(1.0, max(0.0, deadline - time.monotonic())))
                    continue
                if len(self._sessions) + self._reserved < limit:
                    continue
            raise AtCapacity(
                f"{live} sessions are live, the limit (server.max_live_sessions = {limit}), and none is idle "
                "enough to sleep; retry when one has finished, or delete one"
            )

    def live_limit(self) -> int:
        """Sessions live at once at most: ``max_live_sessions``, raised to the seats of the classes (0: none)."""
        limit = self.settings.max_live_sessions
        return limit if limit <= 0 else max(limit, min(self.class_seats, self.settings.max_class_seats))

    def _register(self, session_id: str, session: Session, slot: _Slot | None) -> None:
        """``session`` is live from now on (caller holds the lock): its followers hear it before anyone else can
        change it, and ``slot`` is its place."""
        for listener in self._followers.get(session_id, []):
            session.listeners.append(listener)
        self._sessions[session_id] = session
        self._used[session_id] = time.monotonic()
        self._hand_over(slot)

    # ------------------------------------------------------------------ following

    def follow(self, session_id: str, listener: Callable[[Session, SessionEvent], None]) -> None:
        """Call ``listener(session, event)`` on every event of ``session_id`` from now on, whichever object the
        session is: one woken from sleep (or resumed) is a new Session, and it is heard from its first event.
        Following a session twice with the same listener changes nothing."""
        with self._lock:
            followers = self._followers.setdefault(session_id, [])
            if listener in followers:
                return
            followers.append(listener)
            session = self._sessions.get(session_id)
            if session is not None:
                session.listeners.append(listener)

    def unfollow(self, session_id: str, listener: Callable[[Session, SessionEvent], None]) -> None:
        """Stop following (the live object too); unknown listeners are ignored."""
        with self._lock:
            followers = self._followers.get(session_id, [])
            if listener in followers:
                followers.remove(listener)
            if not followers:
                self._followers.pop(session_id, None)
            session = self._sessions.get(session_id)
        if session is not None and listener in session.listeners:
            with contextlib.suppress(ValueError):
                session.listeners.remove(listener)

    def _hand_over(self, slot: _Slot | None) -> None:
        """``slot``'s session is registered now (caller holds the lock): the slot is its place from now on."""
        if slot is not None and not slot.used:
            slot.used = True
            self._reserved -= 1
            self._changed.notify_all()

    def _give_back(self, slot: _Slot | None) -> None:
        """Give back a slot no session took (the create or wake failed)."""
        if slot is None:
            return
        with self._lock:
            self._hand_over(slot)

    # ------------------------------------------------------------------ delete and close

    def delete(self, session_id: str) -> None:
        """Forget a session (live, interrupted or damaged): its running job is killed, its journal marked deleted
        and its folder moved to the trash (workbench/journal/trash.py), which keeps it until its age or size limit."""
        with self._lock:
            session = self._sessions.pop(session_id, None)
            self._used.pop(session_id, None)
            self._followers.pop(session_id, None)
            dormant = self._dormant.pop(session_id, None) if session is None else None
        if session is None and dormant is None:
            raise NotFound(f"session {session_id!r}: unknown")
        directory = None
        if session is not None:
            session.deleted = True  # a request this cuts off answers Gone (410), not "retry"
            if session.journal is not None:
                directory = session.journal.directory
                with contextlib.suppress(OSError):
                    session.journal.append("deleted")
            session.close()
            for hook in list(self.on_delete):
                hook(session)
        elif dormant is not None:
            directory = dormant.directory
            try:
                writer = JournalWriter.reopen(read_journal(dormant.directory))
            except JournalBusyError as exc:
                with self._lock:
                    self._dormant[session_id] = dormant
                raise Conflict(str(exc)) from None
            except ValueError:  # unreadable: nothing to mark, it goes to the trash as it is
                writer = None
            if writer is not None:
                try:  # a full disk: the folder still goes to the trash (a rename needs no space)
                    writer.append("deleted")
                except OSError as exc:
                    log.warning("session %s: cannot mark the journal deleted: %s", session_id, exc)
                finally:
                    writer.close()
        if directory is not None:
            self._trash(directory)

    def _trash(self, directory: Path) -> None:
        """Move a deleted session's folder to the trash and prune the trash (best effort: a disk error is logged)."""
        try:
            move_to_trash(directory)
            prune(self.settings.data_dir, self.settings.trash_max_bytes, self.settings.trash_max_age)
        except OSError as exc:
            log.error("trash: cannot move %s: %s", directory, exc)

    def close(self) -> None:
        """Kill every running job, stop every session's auto mode, close the journals (shutdown)."""
        if self._sweeper is not None:
            self._sweeper.close()
        sessions = self.list()
        for session in sessions:  # first kill every worker: nothing waits on a long job below
            if session.worker is not None:
                session.worker.close()
        for session in sessions:
            session.close(timeout=3.0)
        if self.engine is not None:
            self.engine.close()
        self.ceilings.close()
