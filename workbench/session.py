"""One supervised scan: the planner, the cell and the state machine a person drives.

States (``Session.state``)::

    new ──capture──► capturing ──► ready ──plan──► planning ──► planned ──approve──► moving ──► ready
                                     ▲               (plan again: the old plan_id goes stale)       │
                                     └────────────────────────────────────────────────────────────┘
    ready / planned ──step / auto──► auto ──► ready | planned | done
    any busy state ──fault──► error ──retry / approve the restored plan / plan──► ...

``done`` means the planner's termination rule fired; a person may still plan and approve more views from
there. ``error`` keeps the map (a failed step never reaches ``Planner.integrate``) and restores the plan
whose approval failed as pending, so approving it again, ``retry`` (re-do the failed step exactly) or a new
plan all leave it.

Locking: ``_lock`` (an RLock) guards every field and is held only briefly. A long action (capture, plan,
move) first claims the session under the lock by switching to a *busy* state, then runs outside the lock
(:class:`workbench.view_step.ViewStep`, ``Planner.plan``), then publishes its result under the lock. A
second action meanwhile sees the busy state and gets :class:`Conflict`, so two approvals of one plan_id move
the robot exactly once, and status reads never wait for the robot. Every change is journaled as it happens
(:meth:`_emit`), and the same event feeds the session's record (workbench/record.py). Listeners are called
outside the lock with a :class:`SessionEvent`.
"""

from __future__ import annotations

import contextlib
import logging
import secrets
import threading
import time
from collections.abc import Callable
from typing import Any, NoReturn

import numpy as np
import trimesh
from numpy.typing import NDArray

from devices.cell import Cell
from devices.config import DeviceConfig
from devices.protocols import UnreachableError
from planner import Planner, PlannerConfig, Pose
from workbench.auto import AutoRunner
from workbench.engine import JobKilled, SessionWorker
from workbench.errors import Conflict, DeviceFault, Gone, Invalid, NotFound, Unreachable
from workbench.factory import SessionParts
from workbench.journal.rebuild import Rebuilt, rebuild
from workbench.journal.store import Journal, JournalWriter, make_event
from workbench.limits import check_config
from workbench.metrics import coverage
from workbench.planning import plan_in
from workbench.progress import Progress, Tracker
from workbench.record import SessionRecord
from workbench.region import ObjectRegion
from workbench.scan_metrics import ceiling_metrics
from workbench.states import (
    BUSY,
    CAN_PLAN,
    CustomPose,
    Decision,
    DecisionKind,
    FailedStep,
    PendingPlan,
    SceneData,
    SessionEvent,
    State,
)
from workbench.summaries import capture_fields, plan_fields, session_status
from workbench.view_step import ViewOutcome, ViewStep, failure_of

log = logging.getLogger(__name__)
Listener = Callable[["Session", SessionEvent], None]

MUTABLE_SECTIONS = ("termination", "candidates", "partitions")
"""Config sections a running session may change (the planner reads them on every plan); the rest are fixed."""


class Session:
    """A supervised scan of one object. Every state change of a session goes through here."""

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
        """The worker process of the heavy steps (workbench/engine.py); None: they run in this process."""
        self.plan_budget = plan_budget
        self.step_runner = ViewStep(
            self.cell, journal, parts.surface_samples, capture_timeout, move_timeout, worker, capture_budget
        )
        self.record = SessionRecord(session_id, parts.model, config.to_dict(), seed, time.time())
        self.auto = AutoRunner(self)
        self.listeners: list[Listener] = []
        self._lock = threading.RLock()
        self._seq = 0  # events of a session without a journal
        self._state = State.NEW
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
        self.moves = 0
        self.ceiling: float | None = None
        """The reachable-coverage ceiling of a simulated session, once computed (workbench/ceilings.py)."""
        self.request_ceiling: Callable[[], None] | None = None
        """Starts computing ``ceiling`` (set by the registry for sessions with a ground truth)."""
        self.progress = Tracker(self._on_progress)
        """The long operation running now (a plan: its stages as the planner reports them)."""
        self._stop_plan = False  # Stop asked for the running plan
        self.deleted = False
        """Set by the registry's delete before it closes the session: a request it cut off answers Gone."""

    # ------------------------------------------------------------------ reading

    @property
    def journal(self) -> JournalWriter | None:
        """The session's journal, given once at construction (the view step writes its frames to the same one;
        nothing sets it later, so no part of a session can hold a stale journal)."""
        return self._journal

    @property
    def state(self) -> State:
        return self._state

    @property
    def pending(self) -> PendingPlan | None:
        return self._pending

    def status(self) -> dict[str, Any]:
        """The session summary of ``GET /api/sessions/{id}``."""
        with self._lock:
            failed = self._failed
            return {"planner": self.evaluator} | session_status(
                self.record,
                state=self._state,
                source=str(self.source.get("kind", "sim")),
                pending=self._pending,
                selected=self._selected,
                custom=self._custom,
                error=self._error or self._journal_error,
                retry=None if failed is None or self._state != State.ERROR else str(failed.decision.kind),
                terminated=self._terminated,
                auto_remaining=self.auto.remaining if self._state == State.AUTO else 0,
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
        with self._lock:
            return {**self.record.metrics(), **ceiling_metrics(self.record.iterations, self.ceiling)}

    def export(self) -> dict[str, Any]:
        """The whole session as one JSON document."""
        with self._lock:
            return self.record.export(self.status())

    def plan_for(self) -> PendingPlan:
        """The pending plan, or the last plan when nothing is pending (for inspection). Conflict when none."""
        with self._lock:
            entry = self._pending or self._last
            if entry is None:
                raise Conflict(f"session {self.id}: no plan yet; plan first (state {self._state})")
            return entry

    def scene_data(self) -> SceneData:
        with self._lock:
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
            )

    # ------------------------------------------------------------------ capture and retry

    def capture(self) -> dict[str, Any]:
        """Capture and integrate the first view at the cell's initial pose."""
        with self._lock:
            if self.planner.iteration > 0:
                raise Conflict(f"session {self.id}: already captured; plan and approve the next view")
            self.claim(frozenset({State.NEW, State.ERROR}), State.CAPTURING, "capture")
            self._error = None
        self.notify(SessionEvent.STATE)
        return self.take_view(Decision(DecisionKind.INITIAL, self.cell.initial_pose()), None)

    def retry(self) -> dict[str, Any]:
        """Re-do the step a fault interrupted (the same pose, the same decision). Conflict when there is none."""
        with self._lock:
            step = self._failed
            if self._state != State.ERROR or step is None:
                raise Conflict(f"session {self.id}: nothing to retry (state {self._state})")
            if step.entry is not None:
                if self._pending is not step.entry:
                    raise Conflict(f"session {self.id}: the plan changed since the fault; approve the new plan")
                self._used.add(step.entry.plan_id)
                self._pending = None
            self.claim(frozenset({State.ERROR}), State.CAPTURING if step.entry is None else State.MOVING, "retry")
            self._error = None
            self._emit("retry", action=str(step.decision.kind), plan_id=step.decision.plan_id)
        self.notify(SessionEvent.STATE)
        return self.take_view(step.decision, step.entry)

    # ------------------------------------------------------------------ plan

    def plan(self) -> PendingPlan:
        """Score the candidates and make a new pending plan (an older one goes stale)."""
        with self._lock:
            if self.planner.iteration == 0:
                raise Conflict(f"session {self.id}: no frame yet; capture first")
            before = self.claim(CAN_PLAN, State.PLANNING, "plan")
        self.notify(SessionEvent.STATE)
        try:
            entry = self.make_plan()
        except Exception:
            with self._lock:
                if self._state == State.PLANNING:  # a killed plan left state error with its reason
                    self._state = before
            self.notify(SessionEvent.STATE)
            raise
        self.notify(SessionEvent.PLANNED)
        return entry

    def make_plan(self) -> PendingPlan:
        """Plan (the caller claimed a busy state) and publish the plan as pending.

        With a worker the plan runs there under ``plan_budget``; killed (budget, DELETE, Stop), the session goes
        to state error with the reason (DeviceFault), its map and pending plan unchanged; plan again to go on.
        """
        planner = self.planner
        worker = self._planning_worker()
        self._stop_plan = False
        self.progress.begin("plan", stoppable=worker is not None)
        try:
            if worker is None:
                plan = plan_in(self.cell, planner, self.progress.plan)
            else:  # the worker's cell has this cell's geometry, arm model, joints and plate angle
                q, angle = self.cell.joint_positions(), self.cell.angle
                plan, planner = worker.plan(
                    planner, self.cell.config, self.plan_budget, q, angle, on_progress=self.progress.plan
                )
                if planner.voxel_map.bbox is not None:
                    self.cell.set_object_box(planner.voxel_map.bbox)  # the box the worker's verdicts used
        except ValueError as exc:
            raise Conflict(f"session {self.id}: {exc}") from None
        except JobKilled as exc:
            if self._state == State.AUTO and self.auto.stopping:
                raise  # Stop killed the plan: auto mode ends and the session settles, no error
            if self._stop_plan:  # plan() puts the state back; map and pending plan are unchanged
                raise Conflict(
                    f"session {self.id}: the plan was stopped (POST .../stop); the map and the pending plan are "
                    "unchanged"
                ) from None
            self._plan_killed(str(exc))
        finally:
            self.progress.end()
        entry = PendingPlan(secrets.token_hex(8), plan, time.time())
        with self._lock:
            self.planner = planner
            if self._pending is not None:
                self._stale.add(self._pending.plan_id)
            self._pending = self._last = entry
            self._selected = plan.best_index
            self._custom = None
            self._error = None
            self._failed = None
            self._emit("plan", plan_id=entry.plan_id, **plan_fields(plan))
            if self._state != State.AUTO:
                self._state = State.PLANNED
        return entry

    def stop_plan(self) -> bool:
        """Stop a plan running in the worker (state planning): the job is killed at once, the session goes back
        to its state before the plan, map and pending plan unchanged. True when one was running."""
        with self._lock:
            current = self.progress.current
            if self._state != State.PLANNING or self.worker is None or current is None or not current.stoppable:
                return False
            self._stop_plan = True
        return self.worker.cancel("stopped by the operator")

    def gone(self) -> Gone:
        """The error of a request cut off because this session was deleted meanwhile."""
        return Gone(f"session {self.id} was deleted (DELETE /api/sessions/{self.id}) while this request ran")

    def _plan_killed(self, reason: str) -> NoReturn:
        if self.deleted:
            raise self.gone()
        message = f"stopped: {reason}"
        with self._lock:
            self._state = State.ERROR
            self._error = message
            self._emit("error", message=message, action="plan", restored_plan=None)
        self.notify(SessionEvent.STATE)
        raise DeviceFault(f"session {self.id}: {message}. The map is unchanged; state error: plan again")

    # ------------------------------------------------------------------ inspect and override

    def candidate_of(self, entry: PendingPlan, index: int) -> int:
        if not 0 <= index < len(entry.plan.candidates):
            raise NotFound(f"candidate {index}: unknown (plan {entry.plan_id} has {len(entry.plan.candidates)})")
        return index

    def select(self, index: int) -> None:
        """Highlight candidate ``index`` of the pending plan (from the list or a click in the scene)."""
        with self._lock:
            if self._pending is None:
                raise Conflict(f"session {self.id}: no pending plan to select from (state {self._state})")
            self._selected = self.candidate_of(self._pending, index)
            self._custom = None
        self.notify(SessionEvent.SELECTION)

    def reachability(self, pose: Pose) -> tuple[bool, str]:
        """Whether the cell can take a view at ``pose``: its arm's reach, and not inside or against the object."""
        try:
            self.cell.plan_motion(pose)
        except UnreachableError as exc:
            return False, str(exc)
        if self.planner.iteration > 0:
            inside = self._object_region().inside_reason(pose.translation, self.devices.camera.min_depth)
            if inside is not None:
                return False, inside
        return True, "reachable"

    def set_custom(self, pose: Pose) -> CustomPose:
        """Propose a custom pose (the gizmo); reachability is checked now and again on approval."""
        ok, reason = self.reachability(pose)
        with self._lock:
            if self._pending is None:
                raise Conflict(f"session {self.id}: no pending plan to override (state {self._state})")
            self._custom = CustomPose(pose, ok, reason)
        self.notify(SessionEvent.CUSTOM_POSE)
        return self._custom

    def _object_region(self) -> ObjectRegion:
        with self._lock:
            if self._region is None:
                self._region = ObjectRegion.build(self._occupied, self.planner.cloud, self.config.voxel.resolution)
            return self._region

    # ------------------------------------------------------------------ approve

    def approve(self, plan_id: str, index: int | None = None, pose: Pose | None = None) -> dict[str, Any]:
        """Move to candidate ``index`` (or to ``pose``) of the pending plan ``plan_id``, capture, integrate.

        Conflict for a stale, used or unknown plan_id or a busy session; NotFound for an unknown candidate;
        Unreachable for a target the cell cannot reach (or one inside the object). In all of these nothing moves.
        """
        if (index is None) == (pose is None):
            raise Invalid("approve: give exactly one of 'index' or 'pose'")
        with self._lock:
            entry = self._check_plan_id(plan_id)
            plan = entry.plan
            if pose is None:
                assert index is not None  # exactly one of the two, checked above
                target = plan.candidates[self.candidate_of(entry, index)].T_world_camera
            else:
                target = pose
            ok, reason = self.reachability(target)
            if not ok:
                raise Unreachable(f"approve: target pose is {reason}")
            self.claim(frozenset({State.PLANNED, State.ERROR}), State.MOVING, "approve")
            self._used.add(plan_id)
            self._pending = None
            self._error = None
            kind = DecisionKind.APPROVE if pose is None and index == plan.best_index else DecisionKind.OVERRIDE
            decision = Decision(kind, target, plan_id, index, plan.best_index, custom=pose is not None)
            self.record_decision(decision)
        self.notify(SessionEvent.STATE)
        return self.take_view(decision, entry)

    def _check_plan_id(self, plan_id: str) -> PendingPlan:
        if plan_id in self._used:
            raise Conflict(f"plan_id {plan_id}: already used; plan again")
        if plan_id in self._stale:
            raise Conflict(f"plan_id {plan_id}: stale (a newer plan replaced it)")
        if self._state in BUSY:
            raise Conflict(f"session {self.id} is busy ({self._state}); approve refused")
        if self._pending is None or self._pending.plan_id != plan_id:
            raise Conflict(f"plan_id {plan_id}: not the pending plan of session {self.id}")
        return self._pending

    # ------------------------------------------------------------------ configuration

    def change_config(self, changes: dict[str, Any]) -> dict[str, Any]:
        """Change the sections the planner reads on every plan (``MUTABLE_SECTIONS``); journaled.

        Invalid for another section or a bad value, Conflict while busy. A pending plan stays approvable.
        """
        fixed = sorted(set(changes) - set(MUTABLE_SECTIONS))
        if fixed:
            raise Invalid(
                f"config: {', '.join(fixed)} cannot change during a session (changeable: {', '.join(MUTABLE_SECTIONS)})"
            )
        with self._lock:
            if self._state in BUSY:
                raise Conflict(f"session {self.id} is busy ({self._state}); config change refused")
            try:
                config = self.config.replace(**changes)
            except (ValueError, TypeError) as exc:
                raise Invalid(f"config: {exc}") from None
            check_config(config)
            self.config = self.planner.config = config
            self._terminated = self.planner.terminated
            self._emit("config", changes=changes, config=config.to_dict())
            if self._state in (State.READY, State.DONE):
                self._state = self.settle()
        self.notify(SessionEvent.STATE)
        return config.to_dict()

    # ------------------------------------------------------------------ resume and close

    def restore(self, rebuilt: Rebuilt) -> None:
        """Take over a session rebuilt from its journal (called once, before the session is shared)."""
        with self._lock:
            self.planner = rebuilt.planner
            self.config = rebuilt.config
            self.record = rebuilt.record
            self._seq = len(rebuilt.record.iterations)
            self._pending = rebuilt.pending
            self._last = rebuilt.last
            self._used = set(rebuilt.used)
            self._stale = set(rebuilt.stale)
            self._selected = None if rebuilt.pending is None else rebuilt.pending.plan.best_index
            self.moves = len(rebuilt.captures)
            self._terminated = self.planner.terminated
            if rebuilt.captures:
                from planner import VoxelClass

                self._occupied = self.planner.voxel_map.centers(VoxelClass.OCCUPIED)
            if rebuilt.device_state is not None:
                with contextlib.suppress(ValueError):  # a device that cannot restore just draws fresh noise
                    self.cell.restore_device_state(rebuilt.device_state)
            self._state = State.NEW if self.planner.iteration == 0 else self.settle()

    def _planning_worker(self) -> SessionWorker | None:
        """The worker that plans (and replays) for this session: its own, unless there is none or the cell judges
        reachability its own way (a replay cell), which a worker's planning cell (the config's geometry and arm
        model) could not reproduce."""
        return self.worker if type(self.cell).is_reachable is Cell.is_reachable else None

    def replay(self, journal: Journal, progress: Callable[[str, int, int], None] | None = None) -> Rebuilt:
        """This session's state rebuilt from ``journal`` (a resume, a discard), to :meth:`restore`: in its worker
        when it has one (killed with it on DELETE and at shutdown), else here. ValueError / KeyError / TypeError
        for a journal that cannot be replayed; JobKilled when the worker was killed."""
        samples = self.surface_samples
        worker = self._planning_worker()
        if worker is None:
            truth = None if samples is None else (lambda cloud: coverage(samples, cloud))
            return rebuild(journal, self.cell, truth, progress)
        q, angle = self.cell.joint_positions(), self.cell.angle
        rebuilt = worker.rebuild(journal, self.cell.config, q, angle, samples, progress)
        if rebuilt.planner.voxel_map.bbox is not None:
            self.cell.set_object_box(rebuilt.planner.voxel_map.bbox)  # the box the replayed plans used
        return rebuilt

    def discard_last_view(self) -> dict[str, Any]:
        """Rebuild this session from its journal without its last view (workbench/discard.py)."""
        from workbench.discard import discard_last_view

        return discard_last_view(self)

    def close(self, timeout: float = 30.0) -> None:
        """Kill a running job and the worker, stop auto mode and wait for it (on delete and at shutdown); release
        hanging devices; close the journal."""
        if self.worker is not None:
            self.worker.close()
        self.auto.stop_and_join(timeout, release=self.injector.release if self.injector is not None else None)
        self.listeners.clear()
        if self.journal is not None:
            self.journal.close()
        close_devices = getattr(self.cell, "close", None)  # a hardware cell releases its devices
        if callable(close_devices):
            close_devices()

    # ------------------------------------------------------------------ the steps actions are built from

    def claim(self, allowed: frozenset[State], busy: State, action: str) -> State:
        """Switch to ``busy`` if the state allows ``action``; return the state before (caller holds the lock)."""
        if self._state not in allowed:
            if self._state in BUSY:
                raise Conflict(f"session {self.id} is busy ({self._state}); {action} refused")
            raise Conflict(f"session {self.id}: cannot {action} in state {self._state}")
        before = self._state
        self._state = busy
        return before

    def settle(self) -> State:
        """The resting state after an action (caller holds the lock)."""
        if self._pending is not None:
            return State.PLANNED
        return State.DONE if self._terminated is not None else State.READY

    def consume(self, entry: PendingPlan) -> None:
        """Mark the pending plan ``entry`` used by a decision (auto mode; caller holds the lock)."""
        self._used.add(entry.plan_id)
        self._pending = None

    def record_decision(self, decision: Decision) -> None:
        """Journal a decision (caller holds the lock)."""
        fields = decision.to_json()
        self._emit("decision", decision=fields.pop("kind"), **fields)

    def _emit(self, kind: str, strict: bool = False, **data: Any) -> None:
        """Journal one event and take it into the record (caller holds the lock). A failing disk does not stop
        the session; the problem is reported in its status. ``strict``: a write that fails raises (OSError)
        and the event is not taken (a view that is not journaled is not acknowledged)."""
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

    def take_view(self, decision: Decision, entry: PendingPlan | None) -> dict[str, Any]:
        """Move, capture, integrate (the caller has claimed a busy state); returns the new iteration's record.

        Raises DeviceFault for a device fault, a timeout or a rejected frame, Unreachable when the cell
        refuses the pose; the session is then in state error with the map unchanged.
        """

        def moved() -> None:
            with self._lock:
                self.moves += 1

        try:
            outcome = self.step_runner.run(self.planner, decision.pose, moved)
            self._publish(outcome, decision)
        except Exception as exc:
            self._step_failed(exc, FailedStep(decision, entry))
        self.notify(SessionEvent.CAPTURED)
        return self.record.iterations[-1]

    def _publish(self, outcome: ViewOutcome, decision: Decision) -> None:
        """Journal the view, then take it over. A view whose ``capture`` event cannot be written is not taken
        (OSError, its frame removed again): the caller is never told of a view a restart would not bring back."""
        with self._lock:
            stored = outcome.stored
            try:
                self._emit(
                    "capture",
                    **capture_fields(outcome.report, outcome.voxels, outcome.coverage),
                    frame=None if stored is None else stored[0],
                    frame_sha256=None if stored is None else stored[1],
                    requested_pose=decision.pose.to_dict(),
                    pose=outcome.frame.T_world_camera.to_dict(),
                    decision=str(decision.kind),
                    plan_id=decision.plan_id,
                    device_state=self.cell.device_state(),
                    strict=True,
                )
            except OSError:
                if stored is not None:
                    self.step_runner.discard_frame(stored[0])
                raise
            self.planner = outcome.planner
            self._terminated = self.planner.terminated
            self._occupied = outcome.occupied
            self._region = None
            self._selected = None
            self._custom = None
            self._failed = None
            self._error = None
            if self._state != State.AUTO:
                self._state = self.settle()

    def _step_failed(self, exc: Exception, step: FailedStep) -> NoReturn:
        """Enter state error after a failed step (the map is untouched, the plan pending again); always raises."""
        if self.deleted:
            raise self.gone() from None
        message, error = failure_of(exc, self.id, step.entry is not None)
        with self._lock:
            self._state = State.ERROR
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
            self._emit("error", message=message, action=str(step.decision.kind), restored_plan=restored)
        self.notify(SessionEvent.STATE)
        if error is None:
            raise exc
        raise error from None
