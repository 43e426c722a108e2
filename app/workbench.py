"""One scan session: the planner, the cell and the state machine a person drives.

States (``Workbench.state``)::

    new ──capture──► capturing ──► ready ──plan──► planning ──► planned ──approve──► moving ──► ready
                                     ▲               (plan again: the old plan_id goes stale)       │
                                     └────────────────────────────────────────────────────────────┘
    ready / planned ──step / auto──► auto ──► ready | planned | done
    any busy state ──fault──► error ──retry / approve the restored plan / plan──► ...

``done`` means the planner's termination rule fired; a person may still plan
and approve more views from there. ``error`` keeps the map (a failed step never
reaches ``Planner.integrate``) and restores the plan whose approval failed as
pending, so approving it again, ``retry`` (re-do the failed step exactly) or a
new plan all leave it.

Locking: ``_lock`` (an RLock) guards every field and is held only briefly. A
long action (capture, plan, move) first claims the session under the lock by
switching to a *busy* state, then runs outside the lock, then publishes its
result under the lock. A second action meanwhile sees the busy state and gets
409, so two approvals of one plan_id move the robot exactly once, and status
reads never wait for the robot. Listeners (the 3D scene) are called outside the
lock. Every change is journaled (app/journal.py) as it happens.
"""

from __future__ import annotations

import contextlib
import threading
from typing import Any

import numpy as np

from app.errors import ConflictError, NotFoundError, UnprocessableError
from app.rebuild import Rebuilt
from app.session_core import SessionCore
from app.state import BUSY, CAN_PLAN, CustomPose, PendingPlan, SceneData, State, custom_json, plan_summary
from devices.protocols import UnreachableError
from planner import Pose

__all__ = ["BUSY", "CustomPose", "PendingPlan", "SceneData", "State", "Workbench", "custom_json", "plan_summary"]

MUTABLE_SECTIONS = ("termination", "candidates", "partitions")
"""Config sections a running session may change (the planner reads them on every plan); the rest are fixed."""


class Workbench(SessionCore):
    """A supervised scan of one object. Every state change of a session goes through here."""

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
            failed = self._failed
            return {
                "id": self.id,
                "model": self.model,
                "source": self.source.get("kind", "sim"),
                "state": str(self._state),
                "iteration": self._iteration,
                "coverage": None if last is None else last["coverage"],
                "points": self._points,
                "voxels": dict(self._voxels),
                "pending_plan": None if pending is None else plan_summary(pending),
                "selected": self._selected,
                "custom_pose": None if self._custom is None else custom_json(self._custom),
                "error": self._error or self._journal_error,
                "retry": None if failed is None or self._state != State.ERROR else failed.action,
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

    # ------------------------------------------------------------------ capture and retry

    def capture(self) -> dict[str, Any]:
        """Capture and integrate the first view at the cell's initial pose."""
        with self._lock:
            if self.planner.iteration > 0:
                raise ConflictError(f"session {self.id}: already captured; plan and approve the next view")
            self._claim(frozenset({State.NEW, State.ERROR}), State.CAPTURING, "capture")
            self._error = None
        self._notify("state")
        return self._take_view(self.cell.initial_pose(), {"kind": "initial"}, None)

    def retry(self) -> dict[str, Any]:
        """Re-do the step a fault interrupted (the same pose, the same decision). 409 when there is none."""
        with self._lock:
            step = self._failed
            if self._state != State.ERROR or step is None:
                raise ConflictError(f"session {self.id}: nothing to retry (state {self._state})")
            if step.entry is not None:
                if self._pending is not step.entry:
                    raise ConflictError(f"session {self.id}: the plan changed since the fault; approve the new plan")
                self._used.add(step.entry.plan_id)
                self._pending = None
            self._claim(frozenset({State.ERROR}), State.CAPTURING if step.entry is None else State.MOVING, "retry")
            self._error = None
            plan_id = None if step.entry is None else step.entry.plan_id
            self._record("retry", action=step.action, plan_id=plan_id)
        self._notify("state")
        return self._take_view(step.pose, step.decision, step.entry)

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
        """Whether the cell can take a view at ``pose``: its arm's reach, and not inside or against the object."""
        try:
            self.cell.plan_motion(pose)
        except UnreachableError as exc:
            return False, str(exc)
        inside = self._inside_reason(pose)
        if inside is not None:
            return False, inside
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
        candidate; 422 for an unreachable target (or one inside the object). In all of these nothing moves.
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
            self._claim(frozenset({State.PLANNED, State.ERROR}), State.MOVING, "approve")
            self._used.add(plan_id)
            self._pending = None
            self._error = None
            kind = "approve" if pose is None and index == plan.best_index else "override"
            decision = {
                "kind": kind,
                "plan_id": plan_id,
                "index": index,
                "best_index": plan.best_index,
                "pose": target.to_dict(),
                "custom": pose is not None,
            }
            self._record_decision(decision)
        self._notify("state")
        return self._take_view(target, decision, entry)

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

    # ------------------------------------------------------------------ configuration

    def change_config(self, changes: dict[str, Any]) -> dict[str, Any]:
        """Change the sections the planner reads on every plan (``MUTABLE_SECTIONS``); journaled.

        422 for another section or a bad value, 409 while busy. A pending plan stays approvable.
        """
        from app.limits import check_config

        fixed = sorted(set(changes) - set(MUTABLE_SECTIONS))
        if fixed:
            raise UnprocessableError(
                f"config: {', '.join(fixed)} cannot change during a session (changeable: {', '.join(MUTABLE_SECTIONS)})"
            )
        with self._lock:
            if self._state in BUSY:
                raise ConflictError(f"session {self.id} is busy ({self._state}); config change refused")
            try:
                config = self.config.replace(**changes)
            except (ValueError, TypeError) as exc:
                raise UnprocessableError(f"config: {exc}") from None
            check_config(config)
            self.config = self.planner.config = config
            self.log.config = config.to_dict()
            self._terminated = self.planner.terminated
            self._record("config", changes=changes, config=config.to_dict())
            if self._state in (State.READY, State.DONE):
                self._state = self._settle()
        self._notify("state")
        return config.to_dict()

    # ------------------------------------------------------------------ resume

    def restore(self, rebuilt: Rebuilt) -> None:
        """Take over a session rebuilt from its journal (called once, before the session is shared)."""
        with self._lock:
            self.planner = rebuilt.planner
            self.config = rebuilt.config
            self.log = rebuilt.log
            self._pending = rebuilt.pending
            self._last = rebuilt.last
            self._used = set(rebuilt.used)
            self._stale = set(rebuilt.stale)
            self._selected = None if rebuilt.pending is None else rebuilt.pending.plan.best_index
            self.moves = len(rebuilt.captures)
            self._terminated = self.planner.terminated
            self._iteration = self.planner.iteration
            if rebuilt.captures:
                last = rebuilt.captures[-1]
                self._points = last.report.n_points_total
                self._voxels = dict(last.voxels)
                from planner import VoxelClass

                self._occupied = self.planner.voxel_map.centers(VoxelClass.OCCUPIED)
            if rebuilt.device_state is not None:
                with contextlib.suppress(ValueError):  # a device that cannot restore just draws fresh noise
                    self.cell.restore_device_state(rebuilt.device_state)
            self._state = State.NEW if self.planner.iteration == 0 else self._settle()

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
        """Run ``count`` steps in a background thread; :meth:`stop` ends it after the current action.
        The first fault ends it too (the session is then in state error)."""
        with self._lock:
            if self.planner.iteration == 0:
                raise ConflictError(f"session {self.id}: no frame yet; capture first")
            self._claim(frozenset({State.READY, State.PLANNED, State.DONE}), State.AUTO, "start auto mode")
            self._stop.clear()
            self._auto_remaining = count
            self.log.event("auto_start", count=count)
            self._record("auto_start", count=count)
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
                self._record("auto_stop")
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
                    self._record_decision(decision)
                records.append(self._take_view(target, decision, entry))
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
        """Stop auto mode and wait for it (on delete and at shutdown); release hanging devices; close the journal."""
        self._stop.set()
        if self.injector is not None:
            self.injector.release()
        thread = self._auto_thread
        if thread is not None and thread is not threading.current_thread():
            thread.join(timeout)
        self.listeners.clear()
        if self.journal is not None:
            self.journal.close()
