"""One scan session: the planner, the cell and the state machine a person drives.

States (``Workbench.state``)::

    new ──capture──► capturing ──► ready ──plan──► planning ──► planned ──approve──► moving ──► ready
                                     ▲               (plan again: the old plan_id goes stale)       │
                                     └────────────────────────────────────────────────────────────┘
    ready / planned ──step / auto──► auto ──► ready | planned | done       any busy state ──fault──► error

``done`` means the planner's termination rule fired; a person may still plan
and approve more views from there. ``error`` keeps the map and the last plan;
planning (or the first capture) again leaves it.

Locking: ``_lock`` (an RLock) guards every field and is held only briefly. A
long action (capture, plan, move) first claims the session under the lock by
switching to a *busy* state, then runs outside the lock, then publishes its
result under the lock. A second action meanwhile sees the busy state and gets
409, so two approvals of one plan_id move the robot exactly once, and status
reads never wait for the robot. Listeners (the 3D scene) are called outside the
lock.
"""

from __future__ import annotations

import contextlib
import secrets
import threading
import time
from collections.abc import Callable
from typing import Any

import numpy as np
import trimesh
from numpy.typing import NDArray

from app.errors import ConflictError, DeviceFaultError, NotFoundError, UnprocessableError
from app.records import SessionLog
from app.state import BUSY, CAN_PLAN, CustomPose, PendingPlan, SceneData, State, custom_json, plan_summary
from devices.cell import Cell
from devices.config import DeviceConfig
from devices.protocols import DeviceError, UnreachableError
from planner import Planner, PlannerConfig, Pose

__all__ = ["BUSY", "CustomPose", "PendingPlan", "SceneData", "State", "Workbench", "custom_json", "plan_summary"]


Listener = Callable[["Workbench", str], None]


class Workbench:
    """A supervised scan of one object. Every state change of a session goes through here."""

    def __init__(
        self,
        session_id: str,
        model: str,
        mesh: trimesh.Trimesh,
        cell: Cell,
        config: PlannerConfig,
        devices: DeviceConfig,
        seed: int = 0,
        surface_samples: NDArray[np.float64] | None = None,
    ) -> None:
        self.id = session_id
        self.model = model
        self.mesh = mesh
        self.cell = cell
        self.config = config
        self.devices = devices
        self.seed = seed
        self.planner = Planner(config)
        self.surface_samples = surface_samples
        self.log = SessionLog(session_id, model, config.to_dict(), seed)
        self.listeners: list[Listener] = []
        self._lock = threading.RLock()
        self._state = State.NEW
        self._error: str | None = None
        self._pending: PendingPlan | None = None
        self._last: PendingPlan | None = None
        self._used: set[str] = set()
        self._stale: set[str] = set()
        self._selected: int | None = None
        self._custom: CustomPose | None = None
        self._stop = threading.Event()
        self._auto_thread: threading.Thread | None = None
        self._auto_remaining = 0
        self._terminated: str | None = None  # planner facts cached under the lock, so status never reads
        self._points = 0  # the planner while another thread integrates into it
        self.moves = 0

    # ------------------------------------------------------------------ reading

    @property
    def state(self) -> State:
        return self._state

    @property
    def pending(self) -> PendingPlan | None:
        return self._pending

    def status(self) -> dict[str, Any]:
        """The session summary of ``GET /api/sessions/{id}``."""
        with self._lock:
            pending = self._pending
            last = self.log.iterations[-1] if self.log.iterations else None
            return {
                "id": self.id,
                "model": self.model,
                "state": str(self._state),
                "iteration": self.planner.iteration,
                "coverage": None if last is None else last["coverage"],
                "points": self._points,
                "pending_plan": None if pending is None else plan_summary(pending),
                "selected": self._selected,
                "custom_pose": None if self._custom is None else custom_json(self._custom),
                "error": self._error,
                "terminated": self._terminated,
                "auto_remaining": self._auto_remaining if self._state == State.AUTO else 0,
                "moves": self.moves,
                "seed": self.seed,
            }

    def metrics(self) -> dict[str, Any]:
        """Per-iteration series for the charts and the BIC curves of the last plan."""
        with self._lock:
            return self.log.metrics()

    def export(self) -> dict[str, Any]:
        """The whole session as one JSON document."""
        with self._lock:
            return self.log.export(self.status())

    def plan_for(self) -> PendingPlan:
        """The pending plan, or the last plan when nothing is pending (for inspection). 409 when there is none."""
        with self._lock:
            entry = self._pending or self._last
            if entry is None:
                raise ConflictError(f"session {self.id}: no plan yet; plan first (state {self._state})")
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

    # ------------------------------------------------------------------ transitions

    def _claim(self, allowed: frozenset[State], busy: State, action: str) -> State:
        """Switch to ``busy`` if the state allows ``action``; return the state before. Caller holds the lock."""
        if self._state not in allowed:
            if self._state in BUSY:
                raise ConflictError(f"session {self.id} is busy ({self._state}); {action} refused")
            raise ConflictError(f"session {self.id}: cannot {action} in state {self._state}")
        before = self._state
        self._state = busy
        return before

    def _settle(self) -> State:
        """The resting state after an action. Caller holds the lock."""
        if self._pending is not None:
            return State.PLANNED
        return State.DONE if self._terminated is not None else State.READY

    def _notify(self, event: str) -> None:
        for listener in list(self.listeners):
            try:
                listener(self, event)
            except Exception:  # a broken listener must not break the session
                import logging

                logging.getLogger(__name__).exception("listener failed on %s", event)

    def _fail(self, message: str) -> None:
        with self._lock:
            self._state = State.ERROR
            self._error = message
            self.log.event("error", message=message)
        self._notify("state")

    # ------------------------------------------------------------------ capture

    def capture(self) -> dict[str, Any]:
        """Capture and integrate the first view at the cell's initial pose."""
        with self._lock:
            if self.planner.iteration > 0:
                raise ConflictError(f"session {self.id}: already captured; plan and approve the next view")
            self._claim(frozenset({State.NEW, State.ERROR}), State.CAPTURING, "capture")
            self._error = None
        self._notify("state")
        record = self._take_view(self.cell.initial_pose(), {"kind": "initial"})
        return record

    def _take_view(self, pose: Pose, decision: dict[str, Any]) -> dict[str, Any]:
        """Move, capture, integrate (caller has claimed a busy state). Raises DeviceFaultError / UnprocessableError."""
        try:
            self.cell.move_to(pose)
            with self._lock:
                self.moves += 1
            frame = self.cell.capture()
            report = self.planner.integrate(frame)
            cov = self._coverage()
        except UnreachableError as exc:
            self._fail(str(exc))
            raise UnprocessableError(str(exc)) from None
        except DeviceError as exc:
            self._fail(f"device fault: {exc}")
            raise DeviceFaultError(f"session {self.id}: device fault: {exc} (session is now in state error)") from None
        except ValueError as exc:
            self._fail(f"frame rejected: {exc}")
            raise DeviceFaultError(
                f"session {self.id}: frame rejected: {exc} (session is now in state error)"
            ) from None
        except Exception as exc:  # a bug, not the robot: still never leave the session stuck in a busy state
            self._fail(f"internal error: {type(exc).__name__}: {exc}")
            raise
        with self._lock:
            record = self.log.iteration(report, cov, decision)
            self._terminated = self.planner.terminated
            self._points = report.n_points_total
            self._selected = None
            self._custom = None
            if self._state != State.AUTO:
                self._state = self._settle()
        self._notify("captured")
        return record

    def _coverage(self) -> float | None:
        from nbv.metrics import coverage

        return None if self.surface_samples is None else float(coverage(self.surface_samples, self.planner.cloud))

    # ------------------------------------------------------------------ plan

    def plan(self) -> PendingPlan:
        """Score the candidates and make a new pending plan (an older one goes stale)."""
        with self._lock:
            if self.planner.iteration == 0:
                raise ConflictError(f"session {self.id}: no frame yet; capture first")
            before = self._claim(CAN_PLAN, State.PLANNING, "plan")
        self._notify("state")
        try:
            entry = self._make_plan()
        except Exception:
            with self._lock:
                self._state = before
            raise
        self._notify("planned")
        return entry

    def _make_plan(self) -> PendingPlan:
        try:
            plan = self.planner.plan(reachable=self.cell.is_reachable)
        except ValueError as exc:
            raise ConflictError(f"session {self.id}: {exc}") from None
        entry = PendingPlan(secrets.token_hex(8), plan, time.time())
        with self._lock:
            if self._pending is not None:
                self._stale.add(self._pending.plan_id)
            self._pending = self._last = entry
            self._selected = plan.best_index
            self._custom = None
            self._error = None
            self.log.plan(entry.plan_id, plan)
            if self._state != State.AUTO:
                self._state = State.PLANNED
        return entry

    # ------------------------------------------------------------------ inspect and override

    def candidate_of(self, entry: PendingPlan, index: int) -> int:
        if not 0 <= index < len(entry.plan.candidates):
            raise NotFoundError(f"candidate {index}: unknown (plan {entry.plan_id} has {len(entry.plan.candidates)})")
        return index

    def select(self, index: int) -> None:
        """Highlight candidate ``index`` of the pending plan (from the list or a click in the scene)."""
        with self._lock:
            if self._pending is None:
                raise ConflictError(f"session {self.id}: no pending plan to select from (state {self._state})")
            self._selected = self.candidate_of(self._pending, index)
            self._custom = None
        self._notify("selection")

    def reachability(self, pose: Pose) -> tuple[bool, str]:
        try:
            self.cell.plan_motion(pose)
        except UnreachableError as exc:
            return False, str(exc)
        return True, "reachable"

    def set_custom(self, pose: Pose) -> CustomPose:
        """Propose a custom pose (the gizmo); reachability is checked now and again on approval."""
        ok, reason = self.reachability(pose)
        with self._lock:
            if self._pending is None:
                raise ConflictError(f"session {self.id}: no pending plan to override (state {self._state})")
            self._custom = CustomPose(pose, ok, reason)
        self._notify("custom_pose")
        return self._custom

    # ------------------------------------------------------------------ approve

    def approve(self, plan_id: str, index: int | None = None, pose: Pose | None = None) -> dict[str, Any]:
        """Move to candidate ``index`` (or to ``pose``) of the pending plan ``plan_id``, capture, integrate.

        409 for a stale, used or unknown plan_id or a busy session; 404 for an unknown
        candidate; 422 for an unreachable target. In all of these nothing moves.
        """
        if (index is None) == (pose is None):
            raise UnprocessableError("approve: give exactly one of 'index' or 'pose'")
        with self._lock:
            entry = self._check_plan_id(plan_id)
            plan = entry.plan
            if pose is None:
                assert index is not None
                target = plan.candidates[self.candidate_of(entry, index)].T_world_camera
            else:
                target = pose
            ok, reason = self.reachability(target)
            if not ok:
                raise UnprocessableError(f"approve: target pose is {reason}")
            self._claim(frozenset({State.PLANNED}), State.MOVING, "approve")
            self._used.add(plan_id)
            self._pending = None
            kind = "approve" if pose is None and index == plan.best_index else "override"
            decision = {
                "kind": kind,
                "plan_id": plan_id,
                "index": index,
                "best_index": plan.best_index,
                "pose": target.to_dict(),
                "custom": pose is not None,
            }
            self.log.decision(decision)
        self._notify("state")
        return self._take_view(target, decision)

    def _check_plan_id(self, plan_id: str) -> PendingPlan:
        if plan_id in self._used:
            raise ConflictError(f"plan_id {plan_id}: already used; plan again")
        if plan_id in self._stale:
            raise ConflictError(f"plan_id {plan_id}: stale (a newer plan replaced it)")
        if self._state in BUSY:
            raise ConflictError(f"session {self.id} is busy ({self._state}); approve refused")
        if self._pending is None or self._pending.plan_id != plan_id:
            raise ConflictError(f"plan_id {plan_id}: not the pending plan of session {self.id}")
        return self._pending

    # ------------------------------------------------------------------ step and auto

    def step(self, count: int = 1) -> list[dict[str, Any]]:
        """Plan and take the planner's choice ``count`` times (scripting); stops early when the scan ends."""
        with self._lock:
            if self.planner.iteration == 0:
                raise ConflictError(f"session {self.id}: no frame yet; capture first")
            self._claim(frozenset({State.READY, State.PLANNED, State.DONE}), State.AUTO, "step")
            self._stop.clear()
            self._auto_remaining = count
        self._notify("state")
        return self._run_steps(count, "step")

    def start_auto(self, count: int) -> None:
        """Run ``count`` steps in a background thread; :meth:`stop` ends it after the current action."""
        with self._lock:
            if self.planner.iteration == 0:
                raise ConflictError(f"session {self.id}: no frame yet; capture first")
            self._claim(frozenset({State.READY, State.PLANNED, State.DONE}), State.AUTO, "start auto mode")
            self._stop.clear()
            self._auto_remaining = count
            self.log.event("auto_start", count=count)
            thread = threading.Thread(target=self._auto_main, args=(count,), name=f"auto-{self.id}", daemon=True)
            self._auto_thread = thread
        self._notify("state")
        thread.start()

    def _auto_main(self, count: int) -> None:
        with contextlib.suppress(Exception):  # already recorded as the error state; the thread just ends
            self._run_steps(count, "auto")

    def stop(self) -> bool:
        """Ask auto mode to stop after the current action. True when auto mode was running."""
        with self._lock:
            running = self._state == State.AUTO
            if running:
                self._stop.set()
                self.log.event("auto_stop")
        return running

    def _run_steps(self, count: int, kind: str) -> list[dict[str, Any]]:
        records: list[dict[str, Any]] = []
        try:
            for _ in range(count):
                if self._stop.is_set() or self.planner.terminated is not None:
                    break
                entry = self._make_plan()
                self._notify("planned")
                best = entry.plan.best_index
                if best is None or self._stop.is_set():
                    break
                with self._lock:
                    self._used.add(entry.plan_id)
                    self._pending = None
                    target = entry.plan.candidates[best].T_world_camera
                    decision = {"kind": kind, "plan_id": entry.plan_id, "index": best, "best_index": best}
                    decision["pose"] = target.to_dict()
                    self.log.decision(decision)
                records.append(self._take_view(target, decision))
                with self._lock:
                    self._auto_remaining -= 1
        finally:
            with self._lock:
                if self._state == State.AUTO:
                    self._state = self._settle()
                self._auto_remaining = 0
                self._auto_thread = None
            self._notify("state")
        return records

    def close(self, timeout: float = 30.0) -> None:
        """Stop auto mode and wait for it (on delete and at shutdown)."""
        self._stop.set()
        thread = self._auto_thread
        if thread is not None and thread is not threading.current_thread():
            thread.join(timeout)
        self.listeners.clear()
