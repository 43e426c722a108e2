"""A supervised calibration: the routine of devices/calibration/ on a cell, one approved pose at a time.

A person sees the pose list, previews a pose (the move the arm would make from where it stands: joints, plate
angle, trajectory; nothing moves), approves it (move, capture, fit the spheres) or skips it. Each capture's
spheres and its residual under the latest estimate are in :meth:`CalibrationRun.status`; the estimate is
recomputed after every capture once there are enough (before that its ``note`` says what is missing).
:meth:`CalibrationRun.write` writes it into the cell file (devices/calibration/cellwrite.py keeps the old file).

Refusals, each leaving everything as it was: an unknown pose (NotFound); a pose already captured, a second
request while the arm moves, a write without an estimate or without a cell file (Conflict); a cell file that
cannot be written (Invalid for a file that is no longer a cell file, StorageFault for a write error). A pose the
arm cannot reach, or whose frame shows no sphere of the target, is *skipped* with its reason and the calibration
goes on. A device fault or timeout leaves the pose pending (approve it again to retry) and raises DeviceFault;
the captures so far are kept.
"""

from __future__ import annotations

import logging
import math
import threading
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any

from devices.calibration import (
    Calibration,
    CalibrationError,
    CalibrationResult,
    Capture,
    compare,
    write_calibration,
)
from devices.calibration import estimate as estimate_calibration
from devices.calibration.sim import SimTruth
from devices.protocols import DeviceError, UnreachableError
from devices.timeout import call_with_timeout
from workbench.calibration.journal import CalibrationJournal, capture_from_json, capture_json
from workbench.errors import Conflict, DeviceFault, Invalid, NotFound, StorageFault

log = logging.getLogger(__name__)

PENDING, CAPTURED, SKIPPED = "pending", "captured", "skipped"
"""A pose's status: not visited yet (or a device fault: retry), its capture kept, or skipped (with the reason)."""


@dataclass
class PoseState:
    """What happened at one pose. spheres: fitted of the target's; fit_rms_mm: (K,) each sphere fit's RMS (None:
    not seen); residual_mm: the capture's RMS centre residual under the latest estimate (None: none yet)."""

    index: int
    label: str
    plate_angle_deg: float
    status: str = PENDING
    reason: str | None = None
    spheres: int = 0
    fit_rms_mm: list[float | None] = field(default_factory=list)
    residual_mm: float | None = None

    def to_json(self) -> dict[str, Any]:
        return dict(self.__dict__)


@dataclass(frozen=True, eq=False)
class PosePreview:
    """The move to a pose from the arm's current state: ``motion`` (a devices.cell.Motion) or None and why."""

    index: int
    moves: int
    """How many moves the arm had made when this was planned (a preview is valid until the next one)."""
    motion: Any
    reason: str | None

    def to_json(self) -> dict[str, Any]:
        m = self.motion
        return {
            "index": self.index,
            "reachable": m is not None,
            "reason": self.reason,
            "joints": None if m is None or m.q is None else [float(v) for v in m.q],
            "plate_angle_deg": None if m is None else math.degrees(float(m.angle)),
            "duration": None if m is None else float(m.duration),
        }


Listener = Callable[["CalibrationRun", str], None]


class CalibrationRun:
    """One supervised calibration of ``routine.cell`` (see the module docstring).

    id: its name in the registry. source: what it runs on (``{"kind": "sim", ...}`` or ``{"kind": "hardware",
    "cell": path, "dry_run": bool}``). cell_file: the cell file :meth:`write` writes (None: nothing to write, a
    simulated cell or a dry run). truth: a simulated cell's true values (the status then compares). move_timeout:
    seconds a move and capture may take (0: no deadline).
    """

    def __init__(
        self,
        id: str,
        routine: Calibration,
        source: dict[str, Any],
        cell_file: str | None = None,
        truth: SimTruth | None = None,
        move_timeout: float = 0.0,
        angle_sigma_deg: float = 0.1,
    ) -> None:
        self.id = id
        self.routine = routine
        self.source = dict(source)
        self.cell_file = cell_file
        self.truth = truth
        self.move_timeout = move_timeout
        self.angle_sigma_deg = angle_sigma_deg
        self.listeners: list[Listener] = []
        self._lock = threading.Lock()
        self._busy: str | None = None
        self._moves = 0
        self._poses = [
            PoseState(i, p.label, round(math.degrees(p.plate_angle), 3)) for i, p in enumerate(routine.poses)
        ]
        self._captures: dict[int, Capture] = {}
        self._previews: dict[int, PosePreview] = {}
        self._result: CalibrationResult | None = None
        self._note = "no estimate yet: approve the poses"
        self._written: dict[str, str] | None = None
        self.selected: int | None = None
        """The pose a person previewed last (the views draw its move)."""
        self.journal: CalibrationJournal | None = None
        """Where each pose outcome is journaled before it is acknowledged (workbench/calibration/journal.py)."""

    # ------------------------------------------------------------------ reading

    @property
    def cell(self) -> Any:
        return self.routine.cell

    @property
    def result(self) -> CalibrationResult | None:
        return self._result

    def pose(self, index: int) -> PoseState:
        if not 0 <= index < len(self._poses):
            raise NotFound(f"calibration {self.id}: pose {index} out of range (0..{len(self._poses) - 1})")
        return self._poses[index]

    def preview_of(self, index: int) -> PosePreview | None:
        """The preview of pose ``index`` still valid (planned since the arm's last move), else None."""
        with self._lock:
            p = self._previews.get(index)
            return p if p is not None and p.moves == self._moves else None

    def status(self) -> dict[str, Any]:
        """JSON-ready: the poses and their outcomes, the estimate (or why there is none), the write, the truth."""
        with self._lock:
            result, poses = self._result, [p.to_json() for p in self._poses]
            out: dict[str, Any] = {
                "id": self.id,
                "source": dict(self.source),
                "busy": self._busy,
                "writable": self.cell_file is not None,
                "target": {
                    "spheres": self.routine.target.count,
                    "diameter_mm": self.routine.target.radius * 2000,
                },
                "poses": poses,
                "selected": self.selected,
                "counts": {s: sum(p["status"] == s for p in poses) for s in (PENDING, CAPTURED, SKIPPED)},
                "estimate": None if result is None else result.to_json(),
                "note": self._note,
                "written": self._written,
                "truth": None,
            }
        if result is not None and self.truth is not None:
            checked = compare(result, self.truth, self.routine.T_flange_camera_nominal)
            out["truth"] = {k: v for k, v in checked.items() if k.endswith(("_mm", "_deg")) or k == "nominal_error"}
        return out

    # ------------------------------------------------------------------ acting

    def _claim(self, what: str) -> None:
        with self._lock:
            if self._busy is not None:
                raise Conflict(f"calibration {self.id}: busy ({self._busy}); wait for it to end")
            self._busy = what

    def _release(self) -> None:
        with self._lock:
            self._busy = None

    def _notify(self, event: str) -> None:
        for listener in list(self.listeners):
            try:
                listener(self, event)
            except Exception:  # a listener (a tab's scene) never breaks the calibration
                log.exception("calibration %s: listener failed on %s", self.id, event)

    def preview(self, index: int) -> PosePreview:
        """Plan the move to pose ``index`` from the arm's current state (moves nothing) and select it. A pose the
        arm cannot reach gives a preview with its reason (approving it would skip it)."""
        self.pose(index)
        cached = self.preview_of(index)
        if cached is None:
            self._claim(f"previewing pose {index}")
            try:
                try:
                    motion, reason = self.routine.preview(index), None
                    if motion.q is None or motion.trajectory is None:
                        motion, reason = None, "the arm gave no joint target"
                except UnreachableError as exc:
                    motion, reason = None, str(exc)
                cached = PosePreview(index, self._moves, motion, reason)
                with self._lock:
                    self._previews[index] = cached
            finally:
                self._release()
        with self._lock:
            self.selected = index
        self._notify("selected")
        return cached

    def _journal(self, kind: str, **fields: Any) -> None:
        """Journal one pose outcome before it is applied (StorageFault, nothing applied, when it cannot be)."""
        if self.journal is None:
            return
        try:
            self.journal.append(kind, **fields)
        except (OSError, ValueError) as exc:
            raise StorageFault(f"calibration {self.id}: cannot journal the pose's outcome ({exc})") from None

    def restore(self, events: list[dict[str, Any]]) -> None:
        """Put back the journaled pose outcomes (a restarted server; before the run is shared), then estimate."""
        for event in events:
            pose = self.pose(int(event["index"]))
            if event["kind"] == "capture":
                self._apply_capture(pose, capture_from_json(event["capture"]))
            elif event["kind"] == "skip":
                pose.status, pose.reason, pose.residual_mm = SKIPPED, str(event["reason"]), None
                pose.spheres, pose.fit_rms_mm = 0, []
                self._captures.pop(pose.index, None)
        self._refit()

    def _apply_capture(self, pose: PoseState, capture: Capture) -> None:
        self._captures[pose.index] = capture
        pose.status, pose.reason = CAPTURED, None
        pose.spheres = int(capture.seen.sum())
        pose.fit_rms_mm = [None if math.isnan(r) else round(float(r) * 1000, 4) for r in capture.fit_rms]

    def skip(self, index: int) -> PoseState:
        """Leave pose ``index`` out (a pending one; a captured pose's capture is dropped and the estimate redone)."""
        pose = self.pose(index)
        self._claim(f"skipping pose {index}")
        try:
            self._journal("skip", index=index, reason="skipped by the person")
            with self._lock:
                pose.status, pose.reason, pose.residual_mm = SKIPPED, "skipped by the person", None
                self._captures.pop(index, None)
            self._refit()
        finally:
            self._release()
        self._notify("skipped")
        return pose

    def approve(self, index: int, refit: bool = True) -> PoseState:
        """Move to pose ``index``, capture, fit the spheres; the estimate is redone (unless ``refit`` is false).
        Returns the pose's state: captured, or skipped with the reason (unreachable, no sphere seen). Conflict for
        a captured pose or while busy; DeviceFault (the pose stays pending) when a device fails or times out, or
        the camera delivers a frame that is not one (NaN depths)."""
        pose = self.pose(index)
        if pose.status == CAPTURED:
            raise Conflict(f"calibration {self.id}: pose {index} ({pose.label}) is captured already")
        self._claim(f"moving to pose {index}")
        try:
            skipped_before = len(self.routine.skipped)
            try:
                timeout = self.move_timeout if self.move_timeout > 0 else None
                capture = call_with_timeout(lambda: self.routine.capture(index), timeout, "calibration move")
            except UnreachableError as exc:  # planned but refused by the driver
                capture = None
                self.routine.skipped.append((pose.label, str(exc)))
            except (DeviceError, OSError, ValueError) as exc:
                with self._lock:
                    self._moves += 1  # the arm may have moved part of the way
                    pose.reason = f"device fault: {exc}"
                raise DeviceFault(f"calibration {self.id}: pose {index} ({pose.label}): {exc}") from None
            with self._lock:
                self._moves += 1
            reasons = self.routine.skipped[skipped_before:]
            reason = reasons[-1][1] if reasons else "not captured"
            if capture is None:  # journaled first: a restart keeps what this answer tells
                self._journal("skip", index=index, reason=reason)
            else:
                self._journal("capture", index=index, capture=capture_json(capture))
            with self._lock:
                if capture is None:
                    pose.status, pose.reason = SKIPPED, reason
                    pose.spheres, pose.fit_rms_mm = 0, []
                else:
                    self._apply_capture(pose, capture)
            if refit:
                self._refit()
        finally:
            self._release()
        self._notify("captured" if pose.status == CAPTURED else "skipped")
        return pose

    def approve_all(self, progress: Callable[[PoseState], None] | None = None) -> list[PoseState]:
        """Approve every pending pose in order (the headless path of the page's "approve all"). A device fault
        stops the loop (DeviceFault, the captures so far kept)."""
        done = []
        try:
            for pose in list(self._poses):
                if pose.status == PENDING:
                    done.append(self.approve(pose.index, refit=False))
                    if progress is not None:
                        progress(done[-1])
        finally:
            if done:
                self._estimate_now()
        return done

    def estimate(self, angle_sigma_deg: float | None = None) -> CalibrationResult:
        """The estimate of the captures so far (Invalid naming what is missing when there is none)."""
        if angle_sigma_deg is not None:
            if not (math.isfinite(angle_sigma_deg) and 0 <= angle_sigma_deg <= 5):
                raise Invalid(f"angle_sigma_deg: in [0, 5], got {angle_sigma_deg!r}")
            self.angle_sigma_deg = angle_sigma_deg
        self._estimate_now()
        if self._result is None:
            raise Invalid(self._note)
        return self._result

    def _estimate_now(self) -> None:
        """Refit the estimate under the ``estimating`` claim and tell the listeners."""
        self._claim("estimating")
        try:
            self._refit()
        finally:
            self._release()
        self._notify("estimate")

    def _refit(self) -> None:
        """Redo the estimate from the kept captures (under the caller's claim)."""
        with self._lock:
            captures = [self._captures[i] for i in sorted(self._captures)]
        try:
            result = estimate_calibration(captures, self.routine.target, self.angle_sigma_deg)
            note = f"estimate of {len(result.labels)} captures"
        except CalibrationError as exc:
            result, note = None, str(exc)
        with self._lock:
            self._result, self._note = result, note
            residual = {} if result is None else dict(zip(result.labels, result.residuals_mm, strict=True))
            for p in self._poses:
                r = residual.get(p.label)
                p.residual_mm = None if r is None else round(float(r), 4)

    def write(self) -> dict[str, str]:
        """Write the estimate into the cell file; {"path", "backup"}. Conflict without an estimate or a cell
        file; Invalid / StorageFault when it cannot be written (the file is then as it was)."""
        if self.cell_file is None:
            kind = "a dry run measures the simulator" if self.source.get("dry_run") else "a simulated cell"
            raise Conflict(f"calibration {self.id}: no cell file to write ({kind}, not the cell)")
        self._claim("writing the cell file")
        try:
            result = self._result
            if result is None:
                raise Conflict(f"calibration {self.id}: nothing to write ({self._note})")
            try:
                backup = write_calibration(self.cell_file, result)
            except ValueError as exc:
                raise Invalid(str(exc)) from None
            except OSError as exc:
                raise StorageFault(f"{self.cell_file}: cannot write the calibration ({exc})") from None
            with self._lock:
                self._written = {"path": str(self.cell_file), "backup": str(backup)}
                return dict(self._written)
        finally:
            self._release()

    def close(self) -> None:
        """Release the cell's devices."""
        self.cell.close()
