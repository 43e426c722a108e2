"""The reachable-coverage ceiling of a simulated session, for the coverage chart's dashed line.

The ceiling (:mod:`workbench.evaluation.object_ceiling`: what the union of every reachable candidate view could
cover) depends only on the object, its placement and the cell, so it is computed once per
(mesh, placement, cell) and cached on disk under ``data_dir/ceilings``. It takes a second or two of open3d
ray casting (which holds the GIL), so :class:`CeilingService` computes it in a worker process, one at a
time, when a session's metrics are first asked for; until then (and for sessions without a ground truth)
the metrics say ``"ceiling": null``.
"""

from __future__ import annotations

import logging
import threading
from collections.abc import Callable
from concurrent.futures import Future, ProcessPoolExecutor
from pathlib import Path

import trimesh

from devices.config import DeviceConfig
from planner import PlannerConfig
from workbench.workers.client import worker_context

log = logging.getLogger(__name__)


def compute_ceiling(mesh: trimesh.Trimesh, devices: DeviceConfig, planner: PlannerConfig, cache_dir: Path) -> float:
    """The ceiling of ``mesh`` (table frame, placed) in the simulated cell of ``devices`` (runs in a worker)."""
    from devices.sim import make_sim_cell
    from workbench.evaluation.object_ceiling import cached_ceiling

    cell = make_sim_cell(mesh, devices.camera, devices.cell)
    return cached_ceiling(mesh, cell, devices.camera, planner, cache_dir).coverage


class CeilingService:
    """One worker process (started on first use) that computes ceilings; results reach ``done(value)``."""

    def __init__(self, cache_dir: Path) -> None:
        self.cache_dir = Path(cache_dir)
        self._lock = threading.Lock()
        self._pool: ProcessPoolExecutor | None = None
        self._pending: dict[str, Future[float]] = {}

    def request(
        self,
        key: str,
        mesh: trimesh.Trimesh,
        devices: DeviceConfig,
        planner: PlannerConfig,
        done: Callable[[float], None],
    ) -> None:
        """Compute the ceiling for ``key`` (a session id) unless already under way; ``done`` gets the value."""
        with self._lock:
            if key in self._pending:
                return
            if self._pool is None:  # the workers' forkserver: not a fork of the server and its threads, and ready
                self._pool = ProcessPoolExecutor(1, mp_context=worker_context())  # in milliseconds (open3d loaded)
            future = self._pool.submit(compute_ceiling, mesh, devices, planner, self.cache_dir)
            self._pending[key] = future

        def finished(f: Future[float]) -> None:
            try:
                done(float(f.result()))
            except Exception as exc:  # the chart just has no line
                log.warning("ceiling of session %s: %s", key, exc)

        future.add_done_callback(finished)

    def close(self) -> None:
        with self._lock:
            pool, self._pool = self._pool, None
        if pool is not None:
            pool.shutdown(wait=False, cancel_futures=True)
