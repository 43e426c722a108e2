"""The server's handle on one session's worker process: a job at a time over a Pipe, under a budget, cancellable.

:class:`SessionWorker` starts its process on the first job (a fork of the forkserver, :func:`worker_context`),
ships the render scene once, sends each job with the state it needs and takes the result (or the exception)
back; a job over its budget, cancelled (DELETE, Stop) or whose process died ends with :class:`JobKilled`.
:func:`render_spec` and :func:`offload_rendering` make a simulated camera render in the worker.
"""

from __future__ import annotations

import logging
import multiprocessing
import threading
import time
from collections.abc import Callable, Collection
from multiprocessing.connection import Connection, wait
from pathlib import Path
from typing import Any, Protocol

import numpy as np
from numpy.typing import NDArray

from devices.cell import Cell
from devices.config import CellConfig
from planner import DepthFrame, Planner, Pose
from planner.planner import IntegrationReport, PlanResult
from planner.progress import ProgressFn
from workbench.journal.rebuild import Rebuilt
from workbench.journal.store import Journal
from workbench.journal.timeline import TimelineStep
from workbench.surface.live import SurfaceUpdate
from workbench.workers.child import RenderSpec, TruthSpec, serve

log = logging.getLogger(__name__)
SETUP_TIMEOUT = 60.0
"""Seconds a new worker may take to start and build its render scene."""
_context: Any = None
_context_lock = threading.Lock()


def worker_context() -> Any:
    """The forkserver context, preloading the worker module (created once per server process)."""
    global _context
    with _context_lock:
        if _context is None:
            ctx = multiprocessing.get_context("forkserver")
            # the worker's libraries imported and the default arm loaded here, once (workbench/workers/preload.py:
            # each worker importing open3d and pinocchio itself cost 1-2 s of CPU); no thread started by them and no
            # scene built: a worker builds its own after the fork. threadpoolctl: the fits' BLAS limit (optional)
            ctx.set_forkserver_preload(["workbench.workers.preload", "threadpoolctl"])
            _context = ctx
        return _context


class JobKilled(Exception):  # noqa: N818 - it says what happened to the job
    """A worker job did not finish: over its budget, cancelled (DELETE, Stop) or its process died."""


class Slots(Protocol):
    """What a worker asks of its pool (workbench/workers/pool.py ``Engine``): a running-job slot, and to be
    marked used or forgotten."""

    def acquire(self, cancelled: threading.Event) -> bool: ...

    def release(self) -> None: ...

    def used(self, worker: SessionWorker) -> None: ...

    def forget(self, worker: SessionWorker) -> None: ...


class SessionWorker:
    """One session's worker process. One job at a time; ``cancel`` and budgets kill it."""

    def __init__(self, engine: Slots, name: str, render: RenderSpec | None) -> None:
        self.engine = engine
        self.name = name
        self.render_spec = render
        self.truth: TruthSpec | None = None
        """The ground truth shipped to each new process (the surface is scored in the worker), None: not scored."""
        self.warm: tuple[Any, Any, float, Any] | None = None
        """(cell config, joints, plate angle, planner config) each new process warms its planning cell with (the
        ``warm`` job) after its setup, None: no warm-up."""
        self.busy = False
        self.jobs = 0
        self._job_lock = threading.Lock()  # one job at a time
        self._proc_lock = threading.Lock()  # the process and pipe fields
        self._proc: Any = None
        self._conn: Connection | None = None
        self._cancelled = threading.Event()
        self._reason: str | None = None
        self._kind: str | None = None  # the kind of the job being run (or waiting for a slot), None: none
        self._cancel_lock = threading.Lock()  # a cancel and the start and end of a job: never one's half
        self._closed = False
        self._hurry: Any = None  # the running process's event: a job waits (its warm-up stops early)
        self._asked = False  # a job was asked of this worker: its warm-ups are cut short from then on
        self._queued = 0.0  # seconds jobs have waited for their turn (this worker's lock, a running-job slot)
        self._queued_since: float | None = None  # when the job waiting now began to wait

    @property
    def pid(self) -> int | None:
        """The worker process's id while it runs, else None."""
        proc = self._proc
        return proc.pid if proc is not None and proc.is_alive() else None

    # ------------------------------------------------------------------ jobs

    def plan(
        self,
        planner: Planner,
        cell: CellConfig,
        budget: float,
        q: Any = None,
        angle: float = 0.0,
        on_progress: ProgressFn | None = None,
    ) -> tuple[PlanResult, Planner]:
        """:func:`workbench.planning.plan_in` a device-less cell of ``cell``'s geometry in the worker (for an arm
        model: its kinematics, the arm at joints ``q`` (n,), the plate at ``angle``): (plan, the planner after
        it). ``on_progress`` hears the plan's stages (sent by the worker at most every 0.1 s within a stage)."""
        return self.call("plan", (planner, cell, q, angle), budget, "plan", on_progress)

    def rebuild(
        self,
        journal: Journal,
        cell: CellConfig,
        q: Any,
        angle: float,
        samples: Any,
        on_progress: Callable[[str, int, int], None] | None = None,
    ) -> Rebuilt:
        """:func:`workbench.journal.rebuild.rebuild` of ``journal`` in the worker's planning cell of ``cell``
        (the arm at joints ``q``, the plate at ``angle``; each capture's device state then), coverage against
        ``samples`` (S, 3) when given. No budget (it is as long as the session); DELETE and shutdown kill it.
        ``on_progress`` hears ``(stage, done, total)``."""
        return self._replay("rebuild", journal, cell, q, angle, samples, on_progress)

    def timeline(
        self,
        journal: Journal,
        cell: CellConfig,
        q: Any,
        angle: float,
        samples: Any,
        on_progress: Callable[[str, int, int], None] | None = None,
    ) -> list[TimelineStep]:
        """:func:`workbench.journal.timeline.timeline_of` ``journal`` in the worker's planning cell (arguments as
        :meth:`rebuild`); the worker's surface and the session are left as they are. No budget."""
        return self._replay("timeline", journal, cell, q, angle, samples, on_progress)

    def _replay(
        self,
        kind: str,
        journal: Journal,
        cell: CellConfig,
        q: Any,
        angle: float,
        samples: Any,
        on_progress: Callable[[str, int, int], None] | None,
    ) -> Any:
        """A job that replays ``journal`` in the worker's planning cell (``rebuild``, ``timeline``): no budget,
        ``(stage, done, total)`` progress."""
        report = None if on_progress is None else (lambda value: on_progress(*value))
        return self.call(kind, (journal, cell, q, angle, samples), 0.0, kind, report)

    def integrate(
        self,
        planner: Planner,
        frame: DepthFrame,
        budget: float,
        journal_dir: Path | None = None,
        moving: Any = None,
    ) -> tuple[IntegrationReport, Planner, SurfaceUpdate, Any]:
        """``planner.integrate(frame)`` in the worker: (report, the planner after it, the session's surface after
        it, which the worker keeps; a new worker rebuilds it from the journal in ``journal_dir`` first; what became
        of the move's frames). moving: capture during moves, the frames of the move to the view, its seconds and
        the keep rule (:func:`workbench.session.view_step.integrate_step`), None: none."""
        return self.call("integrate", (planner, frame, journal_dir, moving), budget, "integration")

    def renderer(self, budget: float) -> Callable[[Pose], NDArray[np.float32]]:
        """A ``render(T_table_camera)`` for the simulated camera that runs in the worker."""

        def render(pose: Pose) -> NDArray[np.float32]:
            return self.call("render", pose, budget, "rendering")

        return render

    def _asking(self) -> None:
        """A job is coming: a process still warming up (start_soon holds the job lock meanwhile) stops doing so."""
        with self._proc_lock:
            self._asked = True
            if self._hurry is not None:
                self._hurry.set()

    def call(
        self, kind: str, payload: Any, budget: float, what: str, on_progress: Callable[[Any], None] | None = None
    ) -> Any:
        """Run one job; its result, or the job's own exception, or JobKilled (budget, cancel, a dead worker).
        ``on_progress`` gets what the job reports on the way (``("progress", value)`` messages)."""
        self._asking()
        with self._cancel_lock:
            self._queued_since = time.monotonic()
        try:
            with self._job_lock:
                if self._closed:
                    raise JobKilled(f"{what}: the session is closed")
                with self._cancel_lock:
                    self._cancelled.clear()
                    self._reason = None
                    self._kind = kind
                if not self.engine.acquire(self._cancelled):
                    with self._cancel_lock:
                        self._kind = None
                    raise JobKilled(f"{what}: {self._reason or 'cancelled'}")
                self._done_waiting()
                self.busy = True
                try:
                    return self._run(kind, payload, budget, what, on_progress)
                finally:
                    with self._cancel_lock:
                        self.busy = False
                        self._kind = None
                    self.jobs += 1
                    self.engine.release()
                    self.engine.used(self)
        finally:
            self._done_waiting()

    def _done_waiting(self) -> None:
        """The job that waited for its turn runs now (or gave up): its wait is counted in :meth:`queued`."""
        with self._cancel_lock:
            if self._queued_since is not None:
                self._queued += time.monotonic() - self._queued_since
                self._queued_since = None

    def queued(self) -> float:
        """Seconds this worker's jobs have waited for their turn so far (this worker's lock, a running-job slot of
        the server, shared by every session), the wait going on now included: a device deadline does not count
        them (``devices.timeout.call_with_timeout``'s ``waited``)."""
        with self._cancel_lock:
            now = 0.0 if self._queued_since is None else time.monotonic() - self._queued_since
            return self._queued + now

    def _run(self, kind: str, payload: Any, budget: float, what: str, on_progress: Callable[[Any], None] | None) -> Any:
        conn, proc = self._started()
        try:
            conn.send((kind, payload))
        except (OSError, ValueError):
            self._kill()
            raise JobKilled(f"{what}: {self._reason or 'the worker process died'}") from None
        if self._cancelled.is_set():  # cancelled while the process started
            self._kill()
            raise JobKilled(f"{what}: {self._reason or 'cancelled'}")
        deadline = None if budget <= 0 else time.monotonic() + budget
        while True:
            timeout = None if deadline is None else max(0.0, deadline - time.monotonic())
            ready = wait([conn, proc.sentinel], timeout)
            if conn in ready:
                try:
                    status, result = conn.recv()
                except (EOFError, OSError):
                    break  # killed while answering
                if status == "progress":
                    if on_progress is not None:
                        on_progress(result)
                    continue
                if status == "error":
                    raise result
                return result
            if ready:  # the process ended (killed by cancel, or crashed)
                break
            if deadline is not None and time.monotonic() >= deadline:
                self._reason = f"over its budget of {budget:g} s; the worker was killed"
                self._kill()
                break
        reason = self._reason or f"the worker process died (exit code {proc.exitcode})"
        self._kill()
        raise JobKilled(f"{what}: {reason}")

    def start(self, asked: bool = True) -> None:
        """Start the process now if it is not running (and ship the render scene); JobKilled if it cannot start.
        ``asked``: a job follows (a capture starts its session's worker first), so a warm-up in progress stops."""
        if asked:
            self._asking()
        with self._job_lock:
            if self._closed:
                raise JobKilled("the session is closed")
            self._started()
        self.engine.used(self)

    def start_soon(self) -> None:
        """Start the process in a background thread (a new session answers at once; its first job waits)."""

        def run() -> None:
            try:
                self.start(asked=False)
            except JobKilled as exc:  # the first job will try again and report it
                if not self._closed:
                    log.warning("session %s: %s", self.name, exc)

        threading.Thread(target=run, name=f"nbv-start-{self.name}", daemon=True).start()

    def _started(self) -> tuple[Connection, Any]:
        """The running process and its pipe, started (with its setup, truth and warm-up jobs) if there is none;
        once a job was asked of this worker its warm-up stops at once."""
        with self._proc_lock:
            if self._proc is not None and self._proc.is_alive() and self._conn is not None:
                return self._conn, self._proc
            ctx = worker_context()
            parent, child = ctx.Pipe()
            hurry = ctx.Event()
            if self._asked:
                hurry.set()
            proc = ctx.Process(target=serve, args=(child, hurry), name=f"nbv-worker-{self.name}", daemon=True)
            proc.start()
            child.close()
            self._proc, self._conn, self._hurry = proc, parent, hurry
        if self._closed:  # closed while this process started: it must not outlive its session
            self._kill()
            raise JobKilled("the session is closed")
        log.debug("session %s: worker %d started", self.name, proc.pid)
        for kind, spec in (("setup", self.render_spec), ("truth", self.truth), ("warm", self.warm)):
            if spec is None:
                continue
            try:
                parent.send((kind, spec))
                if not parent.poll(SETUP_TIMEOUT):
                    raise OSError(f"no answer within {SETUP_TIMEOUT:g} s")
                status, result = parent.recv()
            except (EOFError, OSError, TypeError, ValueError) as exc:
                # TypeError / ValueError: the pipe was closed under the send (the session deleted meanwhile, from
                # another thread: multiprocessing then writes to a handle that is None), or a spec that does not pickle
                self._kill()
                if self._closed:
                    raise JobKilled("the session is closed") from None
                raise JobKilled(f"the worker process did not start ({exc or proc.exitcode})") from None
            if status == "error":
                self._kill()
                raise result
        return parent, proc

    # ------------------------------------------------------------------ stopping

    def cancel(self, reason: str = "cancelled", kinds: Collection[str] | None = None) -> bool:
        """Kill the running job now (its caller gets JobKilled with ``reason``). True when one was running.

        kinds: kill it only when it is a job of one of these kinds (``"plan"``, ``"integrate"``...): a Stop of
        a plan or of auto mode leaves another tab's timeline rebuild or refit running. None: whatever runs."""
        with self._cancel_lock:
            if kinds is not None and self._kind not in kinds:
                return False
            self._reason = reason
            self._cancelled.set()
            running = self.busy
            if running:
                self._kill()
        return running

    def stop_idle(self) -> None:
        """Stop the process if no job runs (idle eviction); the next job starts a new one."""
        if self._job_lock.acquire(blocking=False):
            try:
                self._kill()
            finally:
                self._job_lock.release()

    def close(self) -> None:
        """Kill the process (a running job ends with JobKilled) and take no more jobs."""
        self._closed = True
        self.cancel("the session was closed")
        self._kill()
        self.engine.forget(self)

    def _kill(self) -> None:
        with self._proc_lock:
            proc, conn = self._proc, self._conn
            # the process's event too: its last reference, so its five semaphores are unlinked now (a server that
            # uvicorn ends by re-raising SIGTERM runs no exit handlers, and the resource tracker then warned of them)
            self._proc = self._conn = self._hurry = None
        if proc is not None:
            if proc.is_alive():
                proc.kill()
            proc.join(2.0)
        if conn is not None:
            conn.close()


def render_spec(cell: Cell, cell_config: CellConfig) -> RenderSpec | None:
    """What a worker needs to render ``cell``'s camera, when it is the simulated camera (else None)."""
    from devices.sim import SimulatedCamera

    camera: Any = cell.camera
    while not isinstance(camera, SimulatedCamera) and hasattr(camera, "inner"):
        camera = camera.inner  # fault-injection wrappers
    if not isinstance(camera, SimulatedCamera) or camera.mesh is None:
        return None
    mesh = camera.mesh
    return RenderSpec(
        np.asarray(mesh.vertices, dtype=np.float64),
        np.asarray(mesh.faces, dtype=np.int64),
        camera.config,
        cell_config.plate_radius,
        cell_config.plate_thickness,
    )


def truth_spec(mesh: Any, samples: NDArray[np.float64] | None, surface_points: int | None = None) -> TruthSpec | None:
    """What a worker scores the surface against: the session's ground-truth ``mesh`` (a trimesh in the table
    frame) and its ``samples`` (M, 3), the surface sampled with ``surface_points`` (None: the scorer's default);
    None without a ground truth (``samples`` None or an empty mesh)."""
    if samples is None or len(mesh.faces) == 0:
        return None
    vertices = np.asarray(mesh.vertices, dtype=np.float64)
    faces, samples = np.asarray(mesh.faces, dtype=np.int64), np.asarray(samples, dtype=np.float64)
    return TruthSpec(vertices, faces, samples, surface_points)


def offload_rendering(cell: Cell, worker: SessionWorker, budget: float) -> bool:
    """Make ``cell``'s simulated camera render in ``worker`` (noise, pose and faults stay here). True if done."""
    from devices.sim import SimulatedCamera

    camera: Any = cell.camera
    while not isinstance(camera, SimulatedCamera) and hasattr(camera, "inner"):
        camera = camera.inner
    if not isinstance(camera, SimulatedCamera) or worker.render_spec is None:
        return False
    camera.render = worker.renderer(budget)  # type: ignore[method-assign]
    return True
