"""Worker processes for the sessions' heavy work, so the server always answers and a job can be killed.

open3d's ``cast_rays`` and the planner's fits hold the GIL; a thread cannot be stopped. So each live session
gets a worker *process* (:class:`SessionWorker`, running workbench/workers/child.py) for rendering, integration,
fitting and scoring, driven over a Pipe. The session's state machine, its devices and the authoritative
planner stay in the server process: every job carries the planner in and the planner after the job back, so
a worker killed by a budget, by ``DELETE`` or by Stop loses nothing and a fresh one takes the next job.

- **Budgets.** A job over its budget (``plan_budget``, ``capture_budget``) is killed: :class:`JobKilled`
  names the job and the budget; the session goes to state error, the map unchanged, retry possible.
- **Cancel.** :meth:`SessionWorker.cancel` kills the running job at once (its caller gets JobKilled).
- **Slots.** At most ``max_running_jobs`` jobs run at once (default ``os.cpu_count()``); others wait.
- **Idle workers.** Beyond ``max_idle_workers`` the least recently used idle worker is stopped; it is
  started again (and the render scene shipped again) on its session's next job.

Processes come from a forkserver that preloaded workbench/workers/child.py: a new worker is a fork of a small,
single-threaded process (not of the server with its threads), ready in milliseconds.
"""

from __future__ import annotations

import logging
import os
import threading

from workbench.workers.child import RenderSpec
from workbench.workers.client import SessionWorker, worker_context

log = logging.getLogger(__name__)


def warm_up() -> None:
    """Start the forkserver (it imports the planner and open3d once) so the first session does not wait."""
    worker_context()
    from multiprocessing import forkserver

    try:
        forkserver.ensure_running()
    except Exception as exc:  # the first worker will say what is wrong
        log.warning("worker processes: cannot start the forkserver: %s", exc)


class Engine:
    """The worker processes of one registry: running-job slots and idle-worker eviction."""

    def __init__(self, max_running_jobs: int = 0, max_idle_workers: int = 4) -> None:
        self.max_running = max_running_jobs or os.cpu_count() or 1
        self.max_idle = max_idle_workers
        self._slots = threading.BoundedSemaphore(self.max_running)
        self._lock = threading.Lock()
        self._workers: list[SessionWorker] = []  # least recently used first
        threading.Thread(target=warm_up, name="nbv-forkserver", daemon=True).start()

    def worker(self, name: str, render: RenderSpec | None = None) -> SessionWorker:
        """A worker for session ``name`` (its process starts on the first job)."""
        worker = SessionWorker(self, name, render)
        with self._lock:
            self._workers.append(worker)
        return worker

    def forget(self, worker: SessionWorker) -> None:
        with self._lock:
            if worker in self._workers:
                self._workers.remove(worker)

    def used(self, worker: SessionWorker) -> None:
        """Mark ``worker`` most recently used and stop the oldest idle ones beyond ``max_idle``."""
        with self._lock:
            if worker in self._workers:
                self._workers.remove(worker)
                self._workers.append(worker)
            alive = [w for w in self._workers if w.pid is not None and not w.busy]
            evict = alive[: max(0, len(alive) - self.max_idle)]
        for old in evict:
            old.stop_idle()

    def acquire(self, cancelled: threading.Event) -> bool:
        """Wait for a running-job slot; False when ``cancelled`` is set first."""
        while not cancelled.is_set():
            if self._slots.acquire(timeout=0.05):
                return True
        return False

    def release(self) -> None:
        self._slots.release()

    def close(self) -> None:
        """Stop every worker (server shutdown)."""
        with self._lock:
            workers = list(self._workers)
        for worker in workers:
            worker.close()
