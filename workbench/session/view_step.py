"""Taking one view, the device half of an approve: move, capture (each under a deadline), store, integrate (the
map, then the surface). With capture during moves (``CellConfig.move_capture_hz``) the frames the cell takes on
the way are integrated first (:func:`integrate_step`), the kept ones journaled with the view.

:class:`ViewStep` runs outside the session's lock after the session claimed a busy state; it touches no
session field, so the session publishes its :class:`ViewOutcome` under its lock. ``Planner.integrate`` is
atomic and called last, so a device fault, a timeout or a rejected frame leaves the map as it was; a frame
already written to the journal is removed again. :func:`failure_of` turns what went wrong into the
session's error message and the domain error its caller receives.
"""

from __future__ import annotations

import threading
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np
from numpy.typing import NDArray

from devices.cell import Motion, ScanCell
from devices.move_capture import MoveFrame
from devices.protocols import DeviceError, UnreachableError
from devices.timeout import DeviceTimeoutError, call_with_timeout
from planner import DepthFrame, Planner, Pose, VoxelClass
from planner.planner import IntegrationReport
from workbench.errors import DeviceFault, Unreachable, WorkbenchError
from workbench.evaluation.accuracy import GroundTruth, coverage_and_accuracy
from workbench.journal.store import JournalWriter
from workbench.journal.surface import in_step
from workbench.move_frames import KeepRule, MoveIntegration, integrate_step
from workbench.session.summaries import voxel_counts
from workbench.surface.live import LiveSurface, SurfaceUpdate
from workbench.workers.client import JobKilled, SessionWorker


class UnusableFrame(ValueError):  # noqa: N818 - it says what the frame is
    """The planner could not use the frame (``Planner.integrate``'s ValueError: no return, nothing on the object);
    the map is unchanged. The planner's choice then falls back to the next candidate (``ScanLoop.take_view``)."""


@dataclass(frozen=True, eq=False)
class ViewOutcome:
    """One view integrated: the frame, the planner's report and the facts the session caches.

    stored: (frame path in the journal folder, sha256), None without a journal.
    occupied: (K, 3) float64 centres of the occupied voxels after the view (the override check's region).
    """

    frame: DepthFrame
    report: IntegrationReport
    stored: tuple[str, str] | None
    voxels: dict[str, int]
    coverage: float | None
    occupied: NDArray[np.float64]
    planner: Planner
    """The planner after the view (the session's own, or the copy its worker process integrated into)."""
    surface: SurfaceUpdate | None = None
    """The session's surface after the view (workbench/surface/live.py)."""
    accuracy: dict[str, Any] | None = None
    """The cloud's accuracy against the ground truth after the view (``Accuracy.to_json``), None without one."""
    move_seconds: float | None = None
    """The robot seconds of the move to the view (``Motion.duration``: plate turn + trajectory), None unknown."""
    capture_seconds: float | None = None
    """Wall seconds of the capture."""
    moves: MoveIntegration | None = None
    """Capture during moves: what became of the frames taken on the way (None: the cell took none)."""
    move_stored: tuple[tuple[str, str], ...] = ()
    """The kept move frames in the journal: (path, sha256) each, in stamp order."""


@dataclass
class ViewStep:
    """Moves the cell, captures, stores and integrates one view of one session."""

    cell: ScanCell
    journal: JournalWriter | None
    surface_samples: NDArray[np.float64] | None
    capture_timeout: float
    move_timeout: float
    worker: SessionWorker | None = None
    """Where integration (and the simulated camera's rendering) runs; None: in this process."""
    capture_budget: float = 30.0
    """The worker's budget for one integration, seconds (0: none)."""
    truth: GroundTruth | None = None
    """The true surface (simulation): each view's cloud is scored against it (precision, F, chamfer); in this
    process it also scores the surface (a worker has its own)."""
    _moving: threading.Event | None = field(default=None, repr=False)
    """Set when the last move that timed out has really ended (None: no such move)."""
    _move_prior: float = field(default=0.0, repr=False)
    """The slowest move frame's integration seconds of the last move (the next move's first estimate)."""
    _surface: LiveSurface | None = field(default=None, repr=False)
    """The surface when integration runs in this process (a worker keeps its own)."""

    def run(
        self,
        planner: Planner,
        pose: Pose,
        moved: Callable[[], None],
        then: Sequence[Pose] = (),
        motion: Motion | None = None,
    ) -> ViewOutcome:
        """Take the view at ``T_table_camera = pose`` into ``planner``; ``moved()`` is called once the cell moved.
        ``then``: the views the plan expects next (``PlanResult.then_poses``), for the cell's choice of the move.
        ``motion``: the move to run, planned already (an approval's check); None: the cell plans it.

        A move that timed out was stopped (the devices' ``stop()``); the next run waits until it has really
        ended before it moves again (DeviceTimeoutError if it does not within ``move_timeout``): never two moves.
        Raises whatever the devices, the journal, the worker or ``Planner.integrate`` raised (see
        :func:`failure_of`).
        """
        stored: tuple[str, str] | None = None
        move_stored: list[tuple[str, str]] = []
        hz = float(self.cell.config.move_capture_hz)
        taken: list[MoveFrame] = []  # capture during moves: the cell's frames of the move (from its thread)
        try:
            if self.worker is not None:
                self.worker.start()  # a worker that is (re)starting does not count against the device deadlines
            self._wait_for_the_last_move()
            try:
                ran = call_with_timeout(
                    lambda: self.cell.move_to(
                        pose, then=then, motion=motion, capture_hz=hz, on_frame=taken.append if hz > 0 else None
                    ),
                    self.move_timeout,
                    "cell move",
                    self.cell.stop_moving,
                )
            except DeviceTimeoutError as exc:
                self._moving = exc.pending
                raise
            moved()
            move_seconds = float(ran.duration) if ran.timed else None
            t_capture = time.perf_counter()
            try:
                worker = self.worker
                before = 0.0 if worker is None else worker.queued()
                waited = (
                    None if worker is None else (lambda: worker.queued() - before)
                )  # a render's turn, not the camera's
                frame = call_with_timeout(self.cell.capture, self.capture_timeout, "camera capture", waited=waited)
            except DeviceTimeoutError:
                if self.worker is not None:
                    self.worker.cancel("the capture timed out", kinds=("render",))  # a render still running is killed
                raise
            capture_seconds = time.perf_counter() - t_capture
            if self.journal is not None:
                stored = self.journal.write_frame(planner.iteration + 1, frame)
            journal_dir = None if self.journal is None else self.journal.directory
            moving = None
            if taken and move_seconds is not None:
                moving = (list(taken), move_seconds, KeepRule.of(self.cell.config), self._move_prior)
            try:
                if self.worker is None:
                    views = len(planner.views)
                    report, after, moves = integrate_step(planner, frame, moving)  # a ValueError: the map unchanged
                    self._surface = in_step(self._surface, views, journal_dir, self.truth)
                    for kept in [] if moves is None else moves.kept:
                        self._surface.fuse_move_frame(kept.frame, kept.T_world_camera)
                    surface = self._surface.add(frame, report.T_world_camera)
                else:  # works on a copy; the worker keeps the surface
                    report, after, surface, moves = self.worker.integrate(
                        planner, frame, self.capture_budget, journal_dir, moving
                    )
            except ValueError as exc:
                raise UnusableFrame(str(exc)) from exc
            if moves is not None:
                self._move_prior = moves.slowest
            if self.journal is not None and moves is not None:
                for k, kept in enumerate(moves.kept, start=1):
                    move_stored.append(self.journal.write_move_frame(planner.iteration + 1, k, kept.frame))
        except Exception:
            for name in ([] if stored is None else [stored[0]]) + [m[0] for m in move_stored]:
                self.discard_frame(name)
            raise
        cov, measured = coverage_and_accuracy(self.surface_samples, self.truth, after.cloud)
        scores = None if measured is None else measured.to_json()
        occupied = after.voxel_map.centers(VoxelClass.OCCUPIED)
        return ViewOutcome(
            frame,
            report,
            stored,
            voxel_counts(after),
            cov,
            occupied,
            after,
            surface,
            scores,
            move_seconds,
            capture_seconds,
            moves,
            tuple(move_stored),
        )

    def discard_frame(self, name: str) -> None:
        """Remove a stored frame whose view was not taken (rejected, or its event could not be journaled)."""
        if self.journal is not None:
            self.journal.discard_frame(name)

    def _wait_for_the_last_move(self) -> None:
        moving = self._moving
        if moving is None:
            return
        if not moving.wait(self.move_timeout if self.move_timeout > 0 else None):
            raise DeviceTimeoutError(
                f"cell move: the previous move has not ended after {self.move_timeout:g} s more; "
                "no new move is sent (check the arm)",
                moving,
            )
        self._moving = None


def move_fields(outcome: ViewOutcome) -> dict[str, Any]:
    """The ``capture`` event's fields of capture during moves (none when the cell took no frame on the way):
    ``move_frames`` (the kept frames: ``frame``, ``frame_sha256``, ``t`` seconds into the move, ``pose_used`` the
    registered pose, ``points_frame``, ``new_share``; a rebuild integrates them before the view) and
    ``move_capture`` (:meth:`MoveIntegration.to_json`)."""
    moves = outcome.moves
    if moves is None:
        return {}
    stored = outcome.move_stored if outcome.move_stored else ((None, None),) * len(moves.kept)
    return {
        "move_frames": [
            {
                "frame": name,
                "frame_sha256": digest,
                "t": kept.t,
                "pose_used": kept.T_world_camera.to_dict(),
                "points_frame": kept.points_frame,
                "new_share": kept.new_share,
            }
            for kept, (name, digest) in zip(moves.kept, stored, strict=True)
        ],
        "move_capture": moves.to_json(),
    }


def failure_of(exc: Exception, session_id: str, restored_plan: bool) -> tuple[str, WorkbenchError | None]:
    """(the session's error message, the domain error to raise) for an exception of :meth:`ViewStep.run`.

    The error is None for an unexpected exception (a bug, not the robot): the caller re-raises it after
    putting the session in its error state, so it never stays busy.
    """
    if isinstance(exc, UnreachableError):
        return str(exc), Unreachable(f"session {session_id}: {exc}")
    if isinstance(exc, JobKilled):
        message = f"stopped: {exc}"
    elif isinstance(exc, DeviceTimeoutError):
        message = f"device timeout: {exc}"
    elif isinstance(exc, DeviceError):
        message = f"device fault: {exc}"
    elif isinstance(exc, ValueError):
        message = f"frame rejected: {exc}"
    elif isinstance(exc, OSError):
        message = f"journal: cannot store the view ({exc.strerror or exc})"
    else:
        return f"internal error: {type(exc).__name__}: {exc}", None
    hint = "retry" + (" or approve the plan again" if restored_plan else "")
    return message, DeviceFault(f"session {session_id}: {message}. The map is unchanged; state error: {hint}")
