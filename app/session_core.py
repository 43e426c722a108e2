"""The state of one session and the steps every action is built from (the public actions are in workbench.py).

``SessionCore`` holds the planner, the cell, the journal and the state machine's
fields, and implements the two long steps:

- ``_take_view``: move, capture (each under a deadline), store the frame,
  integrate, journal, publish. Any device fault, timeout or rejected frame leaves
  the map untouched (``Planner.integrate`` is atomic and is called last), puts the
  session in state ``error`` with the reason, restores the plan whose approval
  failed as pending, and remembers the step so ``retry`` can re-do it.
- ``_make_plan``: plan and publish a new pending plan.

Both run outside the lock after the caller claimed a busy state; results are
published under the lock. Listeners are called outside it.
"""

from __future__ import annotations

import logging
import secrets
import threading
import time
from collections.abc import Callable
from typing import Any, NoReturn

import numpy as np
import trimesh
from numpy.typing import NDArray

from app.errors import ConflictError, DeviceFaultError, UnprocessableError
from app.journal import JournalWriter
from app.override_check import ObjectRegion
from app.rebuild import best_of, voxel_counts
from app.records import SessionLog
from app.state import BUSY, CustomPose, FailedStep, PendingPlan, State
from devices.cell import Cell
from devices.config import DeviceConfig
from devices.faults import FaultInjector
from devices.protocols import DeviceError, UnreachableError
from devices.timeout import DeviceTimeoutError, call_with_timeout
from planner import Planner, PlannerConfig, Pose, VoxelClass

log = logging.getLogger(__name__)
Listener = Callable[[Any, str], None]


class SessionCore:
    """Fields, locking and the long steps of a session. See :class:`app.workbench.Workbench`."""

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
        *,
        source: dict[str, Any] | None = None,
        injector: FaultInjector | None = None,
        journal: JournalWriter | None = None,
        capture_timeout: float = 30.0,
        move_timeout: float = 120.0,
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
        self.source = source or {"kind": "sim"}
        self.injector = injector
        self.journal = journal
        self.capture_timeout = capture_timeout
        self.move_timeout = move_timeout
        self.log = SessionLog(session_id, model, config.to_dict(), seed)
        self.listeners: list[Listener] = []
        self._lock = threading.RLock()
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
        self._stop = threading.Event()
        self._auto_thread: threading.Thread | None = None
        self._auto_remaining = 0
        # planner facts cached under the lock, so reads never touch the planner while another thread integrates
        self._terminated: str | None = None
        self._iteration = 0  # views integrated *and journaled*: what status reports
        self._points = 0
        self._voxels: dict[str, int] = {"occupied": 0, "frontier": 0, "unknown": 0, "empty": 0}
        self._region: ObjectRegion | None = None
        self._occupied: NDArray[np.float64] = np.zeros((0, 3))
        self.moves = 0

    # ------------------------------------------------------------------ small helpers (caller holds the lock)

    def _claim(self, allowed: frozenset[State], busy: State, action: str) -> State:
        """Switch to ``busy`` if the state allows ``action``; return the state before."""
        if self._state not in allowed:
            if self._state in BUSY:
                raise ConflictError(f"session {self.id} is busy ({self._state}); {action} refused")
            raise ConflictError(f"session {self.id}: cannot {action} in state {self._state}")
        before = self._state
        self._state = busy
        return before

    def _settle(self) -> State:
        """The resting state after an action."""
        if self._pending is not None:
            return State.PLANNED
        return State.DONE if self._terminated is not None else State.READY

    def _record(self, kind: str, **data: Any) -> None:
        """Journal one event. A failing disk does not stop the session; the problem is reported in its status."""
        if self.journal is None:
            return
        try:
            self.journal.append(kind, **data)
        except (OSError, ValueError) as exc:
            self._journal_error = f"journal: cannot write ({exc}); this session may not resume completely"
            log.error("session %s: %s", self.id, self._journal_error)

    def _notify(self, event: str) -> None:
        for listener in list(self.listeners):
            try:
                listener(self, event)
            except Exception:  # a broken listener must not break the session
                log.exception("listener failed on %s", event)

    def _record_decision(self, decision: dict[str, Any]) -> None:
        self.log.decision(decision)
        self._record("decision", decision=decision["kind"], **{k: v for k, v in decision.items() if k != "kind"})

    # ------------------------------------------------------------------ the object region (override check)

    def _object_region(self) -> ObjectRegion:
        with self._lock:
            region = self._region
            if region is None:
                region = ObjectRegion.build(self._occupied, self.planner.cloud, self.config.voxel.resolution)
                self._region = region
            return region

    def _inside_reason(self, pose: Pose) -> str | None:
        if self.planner.iteration == 0:
            return None
        return self._object_region().inside_reason(pose.translation, self.devices.camera.min_depth)

    # ------------------------------------------------------------------ faults

    def _fault(self, message: str, step: FailedStep) -> None:
        """Enter state error after a failed step: the map is untouched, the plan is pending again."""
        with self._lock:
            self._state = State.ERROR
            self._error = message
            self._failed = step
            restored = None
            if step.entry is not None and self._pending is None and step.entry.plan_id not in self._stale:
                self._pending = step.entry
                self._used.discard(step.entry.plan_id)
                restored = step.entry.plan_id
                if step.decision.get("custom"):
                    self._custom = CustomPose(step.pose, True, "reachable")
                else:
                    self._selected = step.decision.get("index")
            self.log.event("error", message=message)
            self._record("error", message=message, action=step.action, restored_plan=restored)
        self._notify("state")

    # ------------------------------------------------------------------ the device step

    def _take_view(self, pose: Pose, decision: dict[str, Any], entry: PendingPlan | None) -> dict[str, Any]:
        """Move, capture, integrate (the caller has claimed a busy state).

        Raises DeviceFaultError (503) for a device fault, a timeout or a rejected frame,
        UnprocessableError (422) when the cell refuses the pose; the session is then in state error.
        """
        step = FailedStep(str(decision["kind"]), pose, decision, entry)
        stored: tuple[str, str] | None = None
        try:
            call_with_timeout(lambda: self.cell.move_to(pose), self.move_timeout, "cell move")
            with self._lock:
                self.moves += 1
            frame = call_with_timeout(self.cell.capture, self.capture_timeout, "camera capture")
            if self.journal is not None:
                stored = self.journal.write_frame(self.planner.iteration + 1, frame)
            report = self.planner.integrate(frame)  # atomic: a ValueError leaves the map as it was
        except Exception as exc:
            if stored is not None and self.journal is not None:
                self.journal.discard_frame(stored[0])
            self._step_failed(exc, step)
        cov = self._coverage()
        voxels = voxel_counts(self.planner)
        occupied = self.planner.voxel_map.centers(VoxelClass.OCCUPIED)
        with self._lock:
            record = self.log.iteration(report, cov, decision)
            self._record(
                "capture",
                iteration=report.iteration,
                frame=None if stored is None else stored[0],
                frame_sha256=None if stored is None else stored[1],
                requested_pose=pose.to_dict(),
                pose=frame.T_world_camera.to_dict(),
                pose_used=report.T_world_camera.to_dict(),
                decision=decision["kind"],
                plan_id=decision.get("plan_id"),
                points_frame=report.n_points_frame,
                points=report.n_points_total,
                voxels=voxels,
                coverage=cov,
                registration=record["registration"],
                device_state=self.cell.device_state(),
            )
            self._terminated = self.planner.terminated
            self._iteration = report.iteration
            self._points = report.n_points_total
            self._voxels = voxels
            self._occupied = occupied
            self._region = None
            self._selected = None
            self._custom = None
            self._failed = None
            self._error = None
            if self._state != State.AUTO:
                self._state = self._settle()
        self._notify("captured")
        return record

    def _step_failed(self, exc: Exception, step: FailedStep) -> NoReturn:
        """Turn an exception of ``_take_view`` into the error state and the HTTP error; always raises."""
        if isinstance(exc, UnreachableError):
            self._fault(str(exc), step)
            raise UnprocessableError(f"session {self.id}: {exc}") from None
        if isinstance(exc, DeviceTimeoutError):
            message = f"device timeout: {exc}"
        elif isinstance(exc, DeviceError):
            message = f"device fault: {exc}"
        elif isinstance(exc, ValueError):
            message = f"frame rejected: {exc}"
        elif isinstance(exc, OSError):
            message = f"journal: cannot store the frame ({exc.strerror or exc})"
        else:  # a bug, not the robot: still never leave the session stuck in a busy state
            self._fault(f"internal error: {type(exc).__name__}: {exc}", step)
            raise exc
        self._fault(message, step)
        hint = "retry (POST .../retry)" + (" or approve the plan again" if step.entry is not None else "")
        raise DeviceFaultError(f"session {self.id}: {message}. The map is unchanged; state error: {hint}") from None

    def _coverage(self) -> float | None:
        from workbench.metrics import coverage

        return None if self.surface_samples is None else float(coverage(self.surface_samples, self.planner.cloud))

    # ------------------------------------------------------------------ plan

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
            self._failed = None
            self.log.plan(entry.plan_id, plan)
            self._record(
                "plan",
                plan_id=entry.plan_id,
                iteration=plan.iteration,
                best=best_of(plan),
                timings={k: float(v) for k, v in plan.timings.items()},
                n_candidates=len(plan.candidates),
                n_eligible=int(sum(s.eligible for s in plan.scores)),
                terminated=plan.terminated,
            )
            if self._state != State.AUTO:
                self._state = State.PLANNED
        return entry
