"""A session worker's warm-up (workbench/workers/child.py ``_Worker.warm``): it fills the reachability cache of the
first plan's candidates while nobody waits, and stops where it is once a job waits (``hurry``); the plans are the
same either way (reachability is a pure function of the view and the object box)."""

from __future__ import annotations

import threading
from collections.abc import Callable

import numpy as np
import pytest

from devices.builtins import resolve_model
from devices.config import CameraConfig, CellConfig
from devices.sim import make_sim_cell
from planner import PlannerConfig
from tests.helpers import SMALL_CONFIG, wait_until
from workbench.workers.child import RenderSpec, _Worker
from workbench.workers.pool import Engine
from workbench.workers.spare import PAUSES, SpareCore


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
    worker.warm_share = 0.0  # never pauses: what is checked here is the cache and the hurry, whatever the load
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


class _Machine:
    """A fake clock and thread CPU time: each step of work takes ``step`` s of wall time, ``share`` of it on CPU."""

    def __init__(self) -> None:
        self.wall = self.cpu = 0.0
        self.share = 1.0
        self.waits: list[float] = []

    def work(self, seconds: float) -> None:
        self.wall += seconds
        self.cpu += seconds * self.share

    def wait(self, seconds: float) -> bool:
        self.waits.append(seconds)
        self.wall += seconds
        return False


def _spare(machine: _Machine, hurry: Callable[[], bool] = lambda: False) -> SpareCore:
    return SpareCore(hurry, machine.wait, clock=lambda: machine.wall, cpu=lambda: machine.cpu)


def test_spare_core_goes_on_alone_and_pauses_then_gives_up_when_the_cores_are_busy() -> None:
    machine = _Machine()
    spare = _spare(machine)
    for _ in range(100):  # alone on its core: 100 steps of 6 ms, never a pause
        assert spare.go()
        machine.work(0.006)
    assert machine.waits == []
    machine.share = 0.5  # another busy thread on its core
    steps = 0
    while spare.go():
        machine.work(0.006)
        steps += 1
    assert machine.waits == list(PAUSES)  # every pause once, then it stops
    assert spare.paused_seconds == pytest.approx(sum(PAUSES))
    assert steps == 4 * (len(PAUSES) + 1)  # a window of work (4 steps of 6 ms) before each measurement


def test_spare_core_starts_over_once_it_has_its_core_again() -> None:
    machine = _Machine()
    spare = _spare(machine)
    machine.share = 0.3
    for _ in range(8):  # two busy windows: two pauses
        assert spare.go()
        machine.work(0.006)
    assert machine.waits == list(PAUSES[:1])
    assert spare.go()
    assert machine.waits == list(PAUSES[:2])
    machine.share = 1.0
    for _ in range(8):
        assert spare.go()
        machine.work(0.006)
    assert spare.paused == 0 and machine.waits == list(PAUSES[:2])  # the next busy window pauses 50 ms again


def test_spare_core_stops_when_a_job_waits_even_mid_pause() -> None:
    machine = _Machine()
    waiting = [False]
    spare = _spare(machine, lambda: waiting[0])
    assert spare.go()
    waiting[0] = True
    assert not spare.go()  # a job waits: no more steps

    machine = _Machine()
    machine.share = 0.2
    arrived = SpareCore(lambda: False, lambda seconds: True, clock=lambda: machine.wall, cpu=lambda: machine.cpu)
    for _ in range(4):
        assert arrived.go()
        machine.work(0.006)
    assert not arrived.go()  # the pause ended because a job arrived: the warm-up ends too


def test_a_start_that_a_job_follows_asks_the_warm_up_to_stop() -> None:
    """A capture starts its session's worker first (``SessionWorker.start()``): that says a job follows, so a
    warm-up in progress stops at once; the create's own start (``start_soon``) lets it run."""
    _, cell = _worker()
    engine = Engine()
    worker = engine.worker("warm-test")
    worker.warm = (cell.config, cell.joint_positions(), cell.angle, PlannerConfig())  # type: ignore[attr-defined]
    try:
        worker.start_soon()  # the default config: 400 candidates to warm, about half a second when idle
        wait_until(lambda: worker._hurry is not None, 60.0, "the worker process started")
        assert not worker._hurry.is_set()  # warming up: nobody asked anything yet
        worker.start()  # returns once the warm-up has stopped (the process was started already)
        assert worker._hurry.is_set() and worker._asked
    finally:
        worker.close()
        engine.close()


class _ClosesOnPickling:
    """A setup spec whose pickling closes its worker first: a session deleted (on another thread) while its new
    worker's start sends the setup jobs, made deterministic."""

    def __init__(self, worker: object) -> None:
        self.worker = worker

    def __reduce__(self) -> tuple[type, tuple[None]]:
        self.worker.close()  # type: ignore[attr-defined]
        return (_ClosesOnPickling, (None,))


def test_a_session_deleted_while_its_worker_starts_ends_the_start_quietly(caplog: pytest.LogCaptureFixture) -> None:
    """The create's background start (start_soon) sends the setup jobs while a delete closes the worker: the pipe
    is closed under the send (multiprocessing writes to a handle that is None: TypeError). The start ends with
    JobKilled("the session is closed"), no process is left, and the background thread raises nothing."""
    from workbench.workers.client import JobKilled

    engine = Engine()
    try:
        worker = engine.worker("closing")
        worker.render_spec = _ClosesOnPickling(worker)  # type: ignore[assignment]
        with pytest.raises(JobKilled, match="the session is closed"):
            worker.start(asked=False)
        assert worker._proc is None and worker._conn is None
        other = engine.worker("closing-soon")
        other.render_spec = _ClosesOnPickling(other)  # type: ignore[assignment]
        errors: list[BaseException] = []
        previous = threading.excepthook
        threading.excepthook = lambda args: errors.append(args.exc_value)  # type: ignore[assignment]
        try:
            other.start_soon()
            wait_until(lambda: other._closed and other._proc is None, 60.0, "the start ended")
            wait_until(
                lambda: not any(t.name == "nbv-start-closing-soon" for t in threading.enumerate()),
                30.0,
                "the start thread ended",
            )
        finally:
            threading.excepthook = previous
        assert errors == []
    finally:
        engine.close()
