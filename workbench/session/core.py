"""The core of a session: its fields, its lock, the one writer of its state, the journal and the listeners.

:class:`SessionCore` alone writes a session's fields. Actions (workbench/session/loop.py, session.py, auto.py)
read them and change them through its methods, and every change of state goes through :meth:`SessionCore.enter`,
which checks the transition table (workbench/session/states.py), claims the busy state, and when the action
ends settles the session (or, on failure, puts back the state it started from).

Locking: ``lock`` (an RLock) guards every field and is held only briefly. A long action (capture, plan, move)
claims the session under the lock by switching to a *busy* state, runs outside the lock
(:class:`workbench.session.view_step.ViewStep`, ``Planner.plan``), then publishes its result under the lock. A
second action meanwhile sees the busy state and gets :class:`Conflict`, so two approvals of one plan_id move the
robot exactly once, and status reads never wait for the robot. Every change is journaled as it happens
(:meth:`emit`), and the same event feeds the session's record (workbench/session/record.py). Listeners are
called outside the lock with a :class:`SessionEvent`.
"""

from __future__ import annotations

import contextlib
import logging
import threading
import time
from collections.abc import Callable, Iterator
from dataclasses import dataclass, field
from typing import Any, Generic, NoReturn, TypeVar

import numpy as np
import trimesh
from numpy.typing import NDArray

from devices.config import DeviceConfig
from planner import Planner, PlannerConfig, PlanResult, VoxelClass
from workbench.errors import Conflict, DeviceFault, Gone, Invalid
from workbench.evaluation.accuracy import GroundTruth
from workbench.evaluation.curves import ceiling_metrics
from workbench.journal.rebuild import Rebuilt
from workbench.journal.store import JournalWriter, make_event
from workbench.progress import Progress, Tracker
from workbench.session.record import SessionRecord
from workbench.session.region import ObjectRegion
from workbench.session.states import BUSY, TRANSITIONS, Action, State
from workbench.session.summaries import capture_fields, plan_fields, session_status
from workbench.session.values import CustomPose, Decision, FailedStep, PendingPlan, SceneData, SessionEvent
from workbench.session.view_step import ViewOutcome, ViewStep, failure_of, move_fields
from workbench.sources.parts import SessionParts
from workbench.surface.export import EXPORT_FORMATS, export_bytes
from workbench.surface.live import SurfaceUpdate, update_block
from workbench.workers.client import SessionWorker

log = logging.getLogger(__name__)
Listener = Callable[[Any, SessionEvent], None]
T = TypeVar("T")


@dataclass(eq=False)
class Claim(Generic[T]):
    """A running action: what its ``prepare`` returned, and what the listeners hear once the session settled."""

    value: T | None
    news: list[SessionEvent] = field(default_factory=list)


class SessionCore:
    """The fields of one supervised scan and the only code that writes them."""

    def __init__(
        self,
        session_id: str,
        parts: SessionParts,
        config: PlannerConfig,
        devices: DeviceConfig,
        seed: int = 0,
        *,
        journal: JournalWriter | None = None,
        capture_timeout: float = 30.0,
        move_timeout: float = 120.0,
        evaluator: str = "projection",
        worker: SessionWorker | None = None,
        plan_budget: float = 60.0,
        capture_budget: float = 30.0,
        surface_points: int | None = None,
    ) -> None:
        self.id = session_id
        self.model = parts.model
        self.mesh: trimesh.Trimesh = parts.mesh
        self.cell = parts.cell
        self.surface_samples = parts.surface_samples
        self.source = parts.source
        self.injector = parts.injector
        self.config = config
        self.devices = devices
        self.seed = seed
        self.evaluator = evaluator
        """The planner's view evaluator (planner/evaluators.py EVALUATORS): "projection", a baseline, "random"."""
        self.planner = Planner(config, evaluator=evaluator)
        self._journal = journal
        self.worker = worker
        """The worker process of the heavy steps (workbench/workers/); None: they run in this process."""
        self.plan_budget = plan_budget
        truth = None
        if parts.surface_samples is not None and len(parts.mesh.faces) > 0:  # a ground truth: accuracy per view
            truth = GroundTruth.of(parts.mesh, parts.surface_samples, surface_points)
        self.step_runner = ViewStep(
            self.cell, journal, parts.surface_samples, capture_timeout, move_timeout, worker, capture_budget, truth
        )
        self.record = SessionRecord(session_id, parts.model, config.to_dict(), seed, time.time())
        self.listeners: list[Listener] = []
        self.lock = threading.RLock()
        self._changed = threading.Condition(self.lock)
        """Notified whenever the state changes (:meth:`wait_until`)."""
        self._seq = 0  # events of a session without a journal
        self._state = State.NEW
        self._published = False  # the running action published a plan or a view
        self._error: str | None = None
        self._journal_error: str | None = None
        self._pending: PendingPlan | None = None
        self._last: PendingPlan | None = None
        self._used: set[str] = set()
        self._stale: set[str] = set()
        self._selected: int | None = None
        self._custom: CustomPose | None = None
        self._failed: FailedStep | None = None
        self._terminated: str | None = None  # planner facts cached under the lock: reads never touch the planner
        self._region: ObjectRegion | None = None
        self._occupied: NDArray[np.float64] = np.zeros((0, 3))
        self._surface: SurfaceUpdate | None = None
        self._auto_remaining = 0
        self.stop_plan_asked = False
        """Stop was asked for the running plan (``ScanLoop.stop_plan``); the plan's failure then restores the state."""
        self.moves = 0
        self.ceiling: float | None = None
        """The reachable-coverage ceiling of a simulated session, once computed (workbench/evaluation/)."""
        self.request_ceiling: Callable[[], None] | None = None
        """Starts computing ``ceiling`` (set by the registry for sessions with a ground truth)."""
        self.progress = Tracker(self._on_progress)
        """The long operation running now (a plan: its stages as the planner reports them)."""
        self.deleted = False
        """Set by the registry's delete before it closes the session: a request it cut off answers Gone."""
        self._compose()

    def _compose(self) -> None:
        """Build the parts made of this session (a subclass's; the core has none)."""

    # ------------------------------------------------------------------ the state machine

    @property
    def state(self) -> State:
        return self._state

    @property
    def journal(self) -> JournalWriter | None:
        """The session's journal, given once at construction (the view step writes its frames to the same one;
        nothing sets it later, so no part of a session can hold a stale journal)."""
        return self._journal

    def close_state(self) -> bool:
        """Close the session for good unless an action runs (then False): every action is refused from now on (it
        is being put to sleep, its journal kept)."""
        with self.lock:
            if self._state in BUSY:
                return False
            self._set_state(State.CLOSED)
            return True

    def gone(self) -> Gone:
        """The error of a request cut off because this session was deleted meanwhile."""
        return Gone(f"session {self.id} was deleted while this request ran")

    @contextlib.contextmanager
    def enter(
        self, action: Action, prepare: Callable[[], T] | None = None, check: Callable[[], object] | None = None
    ) -> Iterator[Claim[T]]:
        """Run ``action``: claim, then settle or restore.

        Under the lock: run ``check`` (refusals more specific than the table's, which change nothing: a used
        plan_id, nothing to retry); refuse the action (Conflict) unless the state is one of its sources
        (TRANSITIONS); run
        ``prepare`` (its own checks, which may refuse it with nothing changed, then what must happen atomically
        with the claim; its result is the claim's ``value``); switch to the action's busy state. The body runs
        outside the lock (an action without a busy state runs wholly under it). When the body ends, the session
        settles (its resting state) and the listeners hear the claim's ``news`` (or that the state changed); when
        it raises, the state it started from comes back, unless the action already published a plan or a view
        (then it settles) or a fault put it in ``error`` (it stays there).
        """
        transition = TRANSITIONS[action]
        busy = transition.busy
        with self.lock:
            if check is not None:
                check()
            before = self._state
            if before not in transition.sources:
                if before in BUSY:
                    raise Conflict(f"session {self.id} is busy ({before}); {transition.label} refused")
                raise Conflict(f"session {self.id}: cannot {transition.label} in state {before}")
            claim = Claim(prepare() if prepare is not None else None)
            if busy is None:  # the whole action under the lock; an error stays an error
                yield claim
                if before != State.ERROR:
                    self._set_state(self._resting())
            else:
                self._published = False
                self._set_state(busy)
        if busy is not None:
            self.notify(SessionEvent.STATE)
            try:
                yield claim
            except BaseException:
                with self.lock:
                    restored = self._state == busy
                    if restored:
                        self._set_state(self._resting() if self._published else before)
                if restored:
                    self.notify(SessionEvent.STATE)
                raise
            with self.lock:
                if self._state == busy:
                    self._set_state(self._resting())
        for event in claim.news or [SessionEvent.STATE]:
            self.notify(event)

    def _set_state(self, state: State) -> None:
        """The one assignment of the state (caller holds the lock)."""
        self._state = state
        self._changed.notify_all()

    def _resting(self) -> State:
        """The state after an action (caller holds the lock)."""
        if self._pending is not None:
            return State.PLANNED
        if self.planner.iteration == 0:
            return State.NEW
        return State.DONE if self._terminated is not None else State.READY

    def wait_until(self, done: Callable[[], bool], timeout: float) -> bool:
        """Wait up to ``timeout`` s, woken at every change of state, until ``done()``; returns ``done()``."""
        with self._changed:
            return self._changed.wait_for(done, timeout)

    # ------------------------------------------------------------------ reading

    @property
    def pending(self) -> PendingPlan | None:
        return self._pending

    @property
    def failed(self) -> FailedStep | None:
        """The step a fault interrupted (retry re-does it), None when there is none."""
        return self._failed

    @property
    def auto_remaining(self) -> int:
        return self._auto_remaining

    def is_used_or_stale(self, plan_id: str) -> str | None:
        """Why ``plan_id`` cannot be approved any more (None: it is neither used nor stale)."""
        if plan_id in self._used:
            return f"plan_id {plan_id}: already used; plan again"
        if plan_id in self._stale:
            return f"plan_id {plan_id}: stale (a newer plan replaced it)"
        return None

    def status(self) -> dict[str, Any]:
        """The session summary (``SessionStatus``, the fields of workbench/session/summaries.py)."""
        with self.lock:
            failed = self._failed
            return session_status(
                self.record,
                state=self._state,
                planner=self.evaluator,
                source=str(self.source.get("kind", "sim")),
                pending=self._pending,
                selected=self._selected,
                custom=self._custom,
                error=self._error or self._journal_error,
                retry=None if failed is None or self._state != State.ERROR else str(failed.decision.kind),
                terminated=self._terminated,
                auto_remaining=self._auto_remaining if self._state == State.AUTO else 0,
                moves=self.moves,
                progress=self.progress_json(),
            )

    def progress_json(self) -> dict[str, Any] | None:
        """``ProgressOut`` of the running long operation, or None."""
        current = self.progress.current
        return None if current is None else current.to_json()

    def _on_progress(self, progress: Progress | None) -> None:
        self.notify(SessionEvent.PROGRESS)

    def metrics(self) -> dict[str, Any]:
        """Per-iteration series for the charts, the BIC curves of the last plan, and the reachable-coverage
        ceiling (null until computed, and without a ground truth; asking starts its computation)."""
        request, self.request_ceiling = self.request_ceiling, None
        if request is not None:
            request()
        with self.lock:
            return {**self.record.metrics(), **ceiling_metrics(self.record.iterations, self.ceiling)}

    def export(self) -> dict[str, Any]:
        """The whole session as one JSON document (with the surface's block, workbench/surface/live.py)."""
        with self.lock:
            return {**self.record.export(self.status()), "surface": update_block(self._surface)}

    def surface_file(self, fmt: str) -> bytes:
        """The reconstructed surface as a ``fmt`` file ('ply', 'obj', 'glb'). Invalid for another format; Conflict
        when there is no surface yet (no view, or none saw the object: the message says why)."""
        if fmt not in EXPORT_FORMATS:
            raise Invalid(f"format: one of {', '.join(EXPORT_FORMATS)}, got {fmt!r}")
        with self.lock:
            update = self._surface
        if update is None or update.mesh is None:
            why = "no view captured yet" if update is None else update.error
            raise Conflict(f"session {self.id}: no surface yet ({why})")
        return export_bytes(update.mesh, fmt)

    def plan_for(self) -> PendingPlan:
        """The pending plan, or the last plan when nothing is pending (for inspection). Conflict when none."""
        with self.lock:
            entry = self._pending or self._last
            if entry is None:
                raise Conflict(f"session {self.id}: no plan yet; plan first (state {self._state})")
            return entry

    def scene_data(self) -> SceneData:
        with self.lock:
            entry = self._pending or self._last
            k = self.cell.intrinsics
            return SceneData(
                session_id=self.id,
                plan=None if entry is None else entry.plan,
                plan_id=None if self._pending is None else self._pending.plan_id,
                views=tuple(self.planner.views),
                cloud=self.planner.cloud,
                selected=self._selected,
                custom=self._custom,
                mesh=self.mesh,
                plate_radius=self.devices.cell.plate_radius,
                fov_y=float(2.0 * np.arctan2(k.height / 2.0, k.fy)),
                aspect=k.width / k.height,
                surface=None if self._surface is None else self._surface.layer,
            )

    def object_region(self) -> ObjectRegion:
        """The seen object (occupied voxels and cloud) an override must stay out of, built once per view."""
        with self.lock:
            if self._region is None:
                self._region = ObjectRegion.build(self._occupied, self.planner.cloud, self.config.voxel.resolution)
            return self._region

    # ------------------------------------------------------------------ the changes actions make

    def clear_error(self) -> None:
        """A new attempt starts: the last error is no longer the news (caller holds the lock)."""
        self._error = None

    def set_selection(self, index: int) -> None:
        """Highlight candidate ``index`` of the pending plan (caller holds the lock)."""
        self._selected = index
        self._custom = None

    def propose(self, custom: CustomPose) -> None:
        """Show ``custom``, a pose a person set, as the view to approve (caller holds the lock)."""
        self._custom = custom

    def take_decision(self, decision: Decision, entry: PendingPlan | None) -> None:
        """Use the pending plan ``entry`` for ``decision`` and journal the decision (caller holds the lock)."""
        if entry is not None:
            self._used.add(entry.plan_id)
            self._pending = None
        fields = decision.to_json()
        self.emit("decision", decision=fields.pop("kind"), **fields)

    def take_retry(self, step: FailedStep) -> None:
        """Re-do the failed ``step``: its plan is used again and the retry journaled (caller holds the lock)."""
        if step.entry is not None:
            self._used.add(step.entry.plan_id)
            self._pending = None
        self._error = None
        self.emit("retry", action=str(step.decision.kind), plan_id=step.decision.plan_id)

    def refuse_move(self, decision: Decision, exc: Exception, fallback: Decision | None) -> None:
        """Journal that the cell refused ``decision``'s move or its frame was unusable (``exc``), and the
        ``fallback`` taken instead (None: no eligible view left), also as a decision (caller holds the lock)."""
        self.emit(
            "refused",
            plan_id=decision.plan_id,
            candidate=decision.index,
            reason=getattr(exc, "reason", "frame_rejected"),
            message=str(exc),
            next=None if fallback is None else fallback.index,
        )
        if fallback is not None:
            fields = fallback.to_json()
            self.emit("decision", decision=fields.pop("kind"), **fields)

    def add_move(self) -> None:
        with self.lock:
            self.moves += 1

    def set_auto_remaining(self, count: int) -> None:
        with self.lock:
            self._auto_remaining = count

    def publish_plan(self, plan: PlanResult, planner: Planner, plan_id: str) -> PendingPlan:
        """A new pending plan (an older one goes stale), journaled."""
        entry = PendingPlan(plan_id, plan, time.time())
        with self.lock:
            self.planner = planner
            if self._pending is not None:
                self._stale.add(self._pending.plan_id)
            self._pending = self._last = entry
            self._selected = plan.best_index
            self._custom = None
            self._error = None
            self._failed = None
            self._published = True
            self.emit("plan", plan_id=entry.plan_id, **plan_fields(plan))
        return entry

    def publish_view(self, outcome: ViewOutcome, decision: Decision) -> None:
        """Journal the view, then take it over (the planner after it). A view whose ``capture`` event cannot be
        written is not taken (OSError, its frame removed again): the caller is never told of a view a restart
        would not bring back."""
        with self.lock:
            stored = outcome.stored
            try:
                self.emit(
                    "capture",
                    strict=True,
                    **capture_fields(outcome.report, outcome.voxels, outcome.coverage),
                    accuracy=outcome.accuracy,
                    frame=None if stored is None else stored[0],
                    frame_sha256=None if stored is None else stored[1],
                    requested_pose=decision.pose.to_dict(),
                    pose=outcome.frame.T_world_camera.to_dict(),
                    decision=str(decision.kind),
                    plan_id=decision.plan_id,
                    device_state=self.cell.device_state(),
                    surface_fscore_5mm=None if outcome.surface is None else outcome.surface.fscore_5mm,
                    move_seconds=outcome.move_seconds,
                    capture_seconds=outcome.capture_seconds,
                    **move_fields(outcome),
                )
            except OSError:
                for name in ([] if stored is None else [stored[0]]) + [m[0] for m in outcome.move_stored]:
                    self.step_runner.discard_frame(name)
                raise
            self.planner = outcome.planner
            self._terminated = self.planner.terminated
            self._occupied = outcome.occupied
            self._surface = outcome.surface
            self._region = None
            self._selected = None
            self._custom = None
            self._failed = None
            self._error = None
            self._published = True

    def fail_step(self, exc: Exception, step: FailedStep) -> NoReturn:
        """Enter state error after a failed view step (the map is untouched, the plan pending again); raises the
        domain error of ``exc`` (Gone when the session was deleted meanwhile)."""
        if self.deleted:
            raise self.gone() from None
        message, error = failure_of(exc, self.id, step.entry is not None)
        with self.lock:
            self._set_state(State.ERROR)
            self._error = message
            self._failed = step
            restored = None
            entry = step.entry
            if entry is not None and self._pending is None and entry.plan_id not in self._stale:
                self._pending = entry
                self._used.discard(entry.plan_id)
                restored = entry.plan_id
                if step.decision.custom:
                    self._custom = CustomPose(step.decision.pose, True, "reachable")
                else:
                    self._selected = step.decision.index
            self.emit("error", message=message, action=str(step.decision.kind), restored_plan=restored)
        self.notify(SessionEvent.STATE)
        if error is None:
            raise exc
        raise error from None

    def fail_plan(self, reason: str) -> NoReturn:
        """Enter state error after a plan killed in its worker (budget); map and pending plan unchanged. Gone when
        the session was deleted meanwhile."""
        if self.deleted:
            raise self.gone()
        message = f"stopped: {reason}"
        with self.lock:
            self._set_state(State.ERROR)
            self._error = message
            self.emit("error", message=message, action="plan", restored_plan=None)
        self.notify(SessionEvent.STATE)
        raise DeviceFault(f"session {self.id}: {message}. The map is unchanged; state error: plan again")

    @property
    def surface(self) -> SurfaceUpdate | None:
        """The reconstructed surface after the last view (workbench/surface/live.py), None before the first."""
        return self._surface

    def take_config(self, config: PlannerConfig, changes: dict[str, Any]) -> None:
        """Take ``config`` (the mutable sections changed by ``changes``), journaled (caller holds the lock)."""
        self.config = self.planner.config = config
        self._terminated = self.planner.terminated
        self.emit("config", changes=changes, config=config.to_dict())

    def take_over(self, rebuilt: Rebuilt) -> None:
        """Take over a session rebuilt from its journal (a resume, a discard): map, record, plans, devices."""
        with self.lock:
            self.planner = rebuilt.planner
            self.config = rebuilt.config
            self.record = rebuilt.record
            self._seq = len(rebuilt.record.iterations)
            self._pending = rebuilt.pending
            self._last = rebuilt.last
            self._used = set(rebuilt.used)
            self._stale = set(rebuilt.stale)
            self._selected = None if rebuilt.pending is None else rebuilt.pending.plan.best_index
            self._custom = None
            self._error = None
            self._failed = None
            self._region = None
            self.moves = len(rebuilt.captures)
            self._surface = rebuilt.surface if rebuilt.captures else None
            self._terminated = self.planner.terminated
            if rebuilt.captures:
                self._occupied = self.planner.voxel_map.centers(VoxelClass.OCCUPIED)
            if rebuilt.device_state is not None:
                with contextlib.suppress(ValueError):  # a device that cannot restore just draws fresh noise
                    self.cell.restore_device_state(rebuilt.device_state)

    # ------------------------------------------------------------------ journal and listeners

    def emit(self, kind: str, strict: bool = False, **data: Any) -> None:
        """Journal one event and take it into the record (caller holds the lock). A failing disk does not stop
        the session; the problem is reported in its status. ``strict``: a write that fails raises (OSError) and
        the event is not taken (a view that is not journaled is not acknowledged)."""
        event = None
        if self.journal is not None:
            try:
                event = self.journal.append(kind, **data)
            except (OSError, ValueError) as exc:
                if strict:
                    raise
                self._journal_error = f"journal: cannot write ({exc}); this session may not resume completely"
                log.error("session %s: %s", self.id, self._journal_error)
        if event is None:
            self._seq += 1
            event = make_event(self._seq, kind, data)
        self.record.apply(event)

    def notify(self, event: SessionEvent) -> None:
        """Tell the listeners (outside the lock); a broken listener must not break the session."""
        for listener in list(self.listeners):
            try:
                listener(self, event)
            except Exception:
                log.exception("listener failed on %s", event)
