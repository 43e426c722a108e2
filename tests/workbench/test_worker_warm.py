"""A session worker's warm-up (workbench/workers/child.py ``_Worker.warm``): it fills the reachability cache of the
first plan's candidates while nobody waits, and stops where it is once a job waits (``hurry``); the plans are the
same either way (reachability is a pure function of the view and the object box)."""

from __future__ import annotations

import threading

import numpy as np

from devices.builtins import resolve_model
from devices.config import CameraConfig, CellConfig
from devices.sim import make_sim_cell
from tests.helpers import SMALL_CONFIG
from workbench.workers.child import RenderSpec, _Worker


def _worker() -> tuple[_Worker, object]:
    _, mesh = resolve_model("l-block")
    cell = make_sim_cell(mesh, CameraConfig(), CellConfig())
    worker = _Worker()
    spec = RenderSpec(
        np.asarray(mesh.vertices),
        np.asarray(mesh.faces),
        CameraConfig(),
        cell.config.plate_radius,
        cell.config.plate_thickness,
    )
    worker.setup(spec)
    return worker, cell


def _attempts(worker: _Worker, cell: object) -> int:
    planning = worker.reach(cell.config, cell.joint_positions(), cell.angle)  # type: ignore[attr-defined]
    assert planning.kinematics is not None
    return len(planning.kinematics.reach._attempts)


def test_warm_fills_the_cache_unless_a_job_waits() -> None:
    idle, cell = _worker()
    idle.warm(cell.config, cell.joint_positions(), cell.angle, SMALL_CONFIG)  # type: ignore[attr-defined]
    assert _attempts(idle, cell) >= SMALL_CONFIG.candidates.count  # every candidate, at least one plate angle

    hurried, cell = _worker()
    waiting = threading.Event()
    waiting.set()  # a capture is already waiting when the warm-up starts
    hurried.hurry = waiting.is_set
    hurried.warm(cell.config, cell.joint_positions(), cell.angle, SMALL_CONFIG)  # type: ignore[attr-defined]
    assert _attempts(hurried, cell) == 0  # the arm model is built, no view was asked about

    late, cell = _worker()
    asked = 0

    def after_ten() -> bool:  # the job arrives during the reachability pass
        nonlocal asked
        asked += 1
        return asked > 11  # the first call is before the scratch frame, then one per candidate

    late.hurry = after_ten
    late.warm(cell.config, cell.joint_positions(), cell.angle, SMALL_CONFIG)  # type: ignore[attr-defined]
    assert 10 <= _attempts(late, cell) < _attempts(idle, cell)
