"""Where the runs of ``nbv bench`` execute: inline, a local process pool, or a Dask cluster.

Every engine runs the same pure function, :func:`execute` (one :class:`~workbench.evaluation.runs.RunTask` in, one
:class:`~workbench.evaluation.runs.RunOutcome` out, never raising for a failure of the run itself), and calls
``done(outcome)`` in the calling process as each run finishes, so the progress bar counts
finished runs and a failed run is reported without losing the others.

- ``local`` (:func:`run_local`): ``--jobs`` worker processes on this machine, forked from a fork
  server that has imported :data:`PRELOAD`; workers load the mesh from the ``--models`` path.
- ``dask`` (:func:`run_dask`): one task per (model, planner, seed, placement) on a Dask
  ``distributed`` cluster: a ``LocalCluster`` of ``--workers`` processes when no ``--address`` is
  given, else the scheduler at ``--address`` (so clusters from ``dask-jobqueue`` on Slurm/PBS or
  ``dask-kubernetes`` work unchanged). **Mesh files travel with the tasks**: the client loads and
  places each mesh once and scatters its vertex and face arrays (:class:`~workbench.evaluation.runs.MeshPayload`) to
  the cluster; workers never read the client's file system. They need this package importable
  (the same environment) and nothing else.
"""

from __future__ import annotations

import json
import multiprocessing
import time
from collections.abc import Callable, Mapping, Sequence
from concurrent.futures import FIRST_COMPLETED, Future, ProcessPoolExecutor, wait
from concurrent.futures.process import BrokenProcessPool

from workbench.evaluation.runs import MeshPayload, RunOutcome, RunTask

PRELOAD = (
    "workbench.evaluation.executors",
    "workbench.evaluation",
    "planner.baselines",
    "devices.sim",
    "open3d",
    "sklearn.mixture",
)
"""Modules the fork server imports once, so a run's process starts in milliseconds, not seconds."""

Done = Callable[[RunOutcome], None]


def one_line(exc: BaseException, limit: int = 300) -> str:
    """``Type: message`` on one line, at most ``limit`` characters."""
    text = " ".join(str(exc).split()) or "(no message)"
    text = f"{type(exc).__name__}: {text}"
    return text if len(text) <= limit else text[: limit - 3] + "..."


def execute(task: RunTask, mesh: MeshPayload | None = None) -> RunOutcome:
    """Run one scan (in a worker or inline); never raises for a failure of the run itself.

    mesh: the placed mesh (then ``task.model`` is not read from disk); None: load ``task.model``.
    """
    t0 = time.perf_counter()
    try:
        if task.threads is None:
            return _execute(task, mesh, t0)
        from threadpoolctl import threadpool_limits

        with threadpool_limits(limits=task.threads):
            return _execute(task, mesh, t0)
    except Exception as exc:  # one run's failure must not lose the others
        outcome = RunOutcome.failed(task, one_line(exc))
        outcome.seconds = time.perf_counter() - t0
        return outcome


def _execute(task: RunTask, mesh: MeshPayload | None, t0: float) -> RunOutcome:
    from devices.config import CameraConfig
    from workbench.evaluation.accuracy import ACCURACY_COLUMNS
    from workbench.evaluation.scan import icp_rejections
    from workbench.evaluation.simulate import simulate
    from workbench.surface.config import surface_config_for
    from workbench.surface.integrator import SurfaceIntegrator
    from workbench.surface.report import surface_block

    camera = CameraConfig(depth_noise_std=task.depth_noise, sensor=task.sensor, calibration=task.calibration)
    surface = SurfaceIntegrator(surface_config_for(camera))

    scan = simulate(
        task.model if mesh is None else task.label,
        task.config,
        planner_name=task.planner,
        size=task.size,
        up=task.up,
        yaw_deg=task.yaw_deg,
        seed=task.seed,
        depth_noise=task.depth_noise,
        pose_noise=task.pose_noise,
        reachable=False,
        arm=task.arm,
        cell=task.cell,
        turn_while_moving=task.turn_while_moving,
        mesh=None if mesh is None else mesh.to_trimesh(),
        sensor=task.sensor,
        calibration=task.calibration,
        on_frame=surface.integrate,
        on_move_frame=surface.integrate,
    )
    outcome = RunOutcome(
        task.label, task.run_planner, task.seed, task.yaw_deg, terminated=scan.result.terminated, arm=task.arm_label
    )
    cell_config = scan.cell.config
    arm_name = "reach_sphere" if cell_config.kinematics == "reach_sphere" else cell_config.arm.urdf
    outcome.refused_moves = scan.result.refused_moves
    outcome.icp_rejected = icp_rejections(scan.result.records)
    for r in scan.result.records:
        outcome.rows.append(
            {
                "model": task.label,
                "planner": task.run_planner,
                "arm": arm_name,
                "seed": task.seed,
                "yaw": task.yaw_deg,
                "iteration": r.index,
                "coverage": r.coverage,
                "points": r.points,
                "plan_seconds": r.plan_seconds,
                "eval_seconds": r.timings.get("score", 0.0),
                "fit_seconds": r.timings.get("cluster", 0.0) + r.timings.get("ellipsoids", 0.0),
                "robot_seconds": r.robot_seconds,
                "move_seconds": r.move_seconds,
                "capture_seconds": r.capture_seconds,
                "motion_planning_seconds": r.motion_planning_seconds,
                "plan_cpu_seconds": r.plan_cpu_seconds,
                "move_frames": len(r.move_frames),
                "move_integration_seconds": None if r.move_capture is None else r.move_capture["integration_seconds"],
                "move_wait_seconds": None if r.move_capture is None else r.move_capture["wait_seconds"],
                "move_coverage": json.dumps(
                    [[f["t"], f["coverage"]] for f in r.move_frames if f["coverage"] is not None]
                ),
                **{k: None if r.accuracy is None else r.accuracy[k] for k in ACCURACY_COLUMNS},
                "surface_fscore_5mm": None,
            }
        )
        outcome.poses.append(r.pose.to_dict())
    if outcome.rows:  # the final surface, scored like the cloud (the same surface samples for recall)
        outcome.rows[-1]["surface_fscore_5mm"] = surface_block(surface, scan.mesh, scan.surface_samples)[1][
            "fscore_5mm"
        ]
    outcome.seconds = time.perf_counter() - t0
    return outcome


# ---------------------------------------------------------------- local


def run_local(tasks: Sequence[RunTask], jobs: int, done: Done) -> None:
    """Run ``tasks`` on this machine, calling ``done`` in this process as each finishes.

    jobs == 1: inline, in order. Otherwise a process pool with ``jobs`` workers and one
    task per worker process (where the platform has no fork server: spawned). If a worker
    dies (crash, out of memory), the runs lost with the pool are retried one at a time, so
    only the run that killed its process is reported as failed.
    """
    if jobs == 1:
        for task in tasks:
            done(execute(task))
        return
    for task in _pool_pass(tasks, jobs, done):
        if _pool_pass([task], 1, done):
            done(RunOutcome.failed(task, "the worker process died (a crash or out of memory)"))


def _pool_pass(tasks: Sequence[RunTask], jobs: int, done: Done) -> list[RunTask]:
    """One process pool over ``tasks``; returns the tasks lost because the pool broke."""
    lost: list[RunTask] = []
    if "forkserver" in multiprocessing.get_all_start_methods():
        context = multiprocessing.get_context("forkserver")
        context.set_forkserver_preload(list(PRELOAD))
    else:  # pragma: no cover - Windows
        context = multiprocessing.get_context("spawn")
    pool = ProcessPoolExecutor(max_workers=min(jobs, len(tasks)), mp_context=context, max_tasks_per_child=1)
    try:
        pending: dict[Future[RunOutcome], RunTask] = {pool.submit(execute, t): t for t in tasks}
        while pending:
            finished, _ = wait(pending, return_when=FIRST_COMPLETED)
            for future in finished:
                task = pending.pop(future)
                try:
                    outcome = future.result()
                except BrokenProcessPool:
                    lost.append(task)
                    continue
                except Exception as exc:  # e.g. a result that cannot be pickled
                    outcome = RunOutcome.failed(task, one_line(exc))
                done(outcome)
    except BaseException:
        pool.shutdown(wait=False, cancel_futures=True)
        raise
    pool.shutdown(wait=True)
    return lost


# ---------------------------------------------------------------- dask


def check_reachable(address: str, timeout: float) -> None:
    """OSError (one line) when nothing accepts TCP connections at ``address`` (``tcp://host:port``), so a
    wrong address fails in seconds instead of after the Dask client's retries."""
    import socket
    from urllib.parse import urlsplit

    parts = urlsplit(address if "://" in address else f"tcp://{address}")
    if parts.scheme not in ("tcp", "tls") or parts.hostname is None or parts.port is None:
        raise OSError(f"expected tcp://host:port, got {address!r}")
    try:
        with socket.create_connection((parts.hostname, parts.port), timeout=timeout):
            pass
    except OSError as exc:
        raise OSError(f"no Dask scheduler at {address} ({exc.strerror or exc})") from None


def run_dask(
    tasks: Sequence[RunTask],
    meshes: Mapping[str, MeshPayload],
    done: Done,
    *,
    address: str | None = None,
    workers: int = 2,
    connect_timeout: float = 30.0,
) -> None:
    """Run ``tasks`` as Dask tasks, calling ``done`` in this process as each finishes.

    meshes: label -> placed mesh, scattered once to the cluster and handed to every task of that
    model. address: an existing scheduler (``tcp://host:port``); None starts a ``LocalCluster`` of
    ``workers`` single-threaded worker processes for this bench and closes it afterwards.
    A task that raises on the worker or whose worker dies for good (``KilledWorker``) becomes a
    failed outcome; the others go on.
    """
    from distributed import Client, LocalCluster, as_completed

    cluster = None
    if address is None:
        cluster = LocalCluster(
            n_workers=workers, threads_per_worker=1, processes=True, dashboard_address=":0", silence_logs=40
        )
        client = Client(cluster)
    else:
        check_reachable(address, min(connect_timeout, 5.0))
        client = Client(address, timeout=connect_timeout)
    try:
        scattered = {label: client.scatter(mesh, hash=False) for label, mesh in meshes.items()}
        futures = {}
        for task in tasks:
            key = f"nbv-run-{task.label}-{task.planner}-s{task.seed}-y{task.yaw_deg:g}-{time.time_ns()}"
            future = client.submit(execute, task, scattered.get(task.label), key=key, pure=False)
            futures[future] = task
        for future in as_completed(futures):
            task = futures[future]
            try:
                outcome = future.result()
            except Exception as exc:  # the task could not run or its worker died
                outcome = RunOutcome.failed(task, one_line(exc))
            done(outcome)
    finally:
        client.close()
        if cluster is not None:
            cluster.close()
