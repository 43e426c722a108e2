"""compare planners on several models in the simulated cell (results.csv, summary.md, plots)

``nbv bench --models l-block mug --planners projection,raycast-apora,raycast-oa,random --views 10 --jobs 2``
runs every (model, planner, seed) combination as one simulated scan (:func:`nbv.run.simulate`),
each in its own worker process (``--jobs`` at a time; ``--jobs 1`` runs inline), and writes

- ``DIR/results.csv``: one row per (model, planner, seed, iteration), rewritten as runs complete;
- ``DIR/runs.json``: one entry per run (poses, stop reason, wall time, error);
- ``DIR/summary.md``, ``DIR/coverage.png``, ``DIR/time.png``: see :mod:`nbv.bench_report`.

Fairness: every planner of a (model, seed) pair gets the same cell, the same first view
(``Cell.initial_pose``), the same seed for camera noise, surface samples and the planner's
random choices. The reachable-coverage ceiling is computed once per (model, seed), in one run
(``projection``'s if it takes part, else the first planner's), and shared by all planners.
A failed run does not stop the others: its one-line error is reported and the exit code is 1.
"""

from __future__ import annotations

import argparse
import json
import multiprocessing
import os
import time
from collections.abc import Callable, Sequence
from concurrent.futures import FIRST_COMPLETED, Future, ProcessPoolExecutor, wait
from concurrent.futures.process import BrokenProcessPool
from pathlib import Path
from typing import Any

from nbv.options import CliError, add_scan_options, planner_config_from_args
from nbv.runs import RunOutcome, RunTask

DEFAULT_PLANNERS = "projection,raycast-apora,raycast-oa,random"

PRELOAD = ("nbv.bench", "nbv.run", "nbv.reachable", "planner.baselines", "devices.sim", "open3d", "sklearn.mixture")
"""Modules the fork server imports once, so a run's process starts in milliseconds, not seconds."""


def one_line(exc: BaseException, limit: int = 300) -> str:
    """``Type: message`` on one line, at most ``limit`` characters."""
    text = " ".join(str(exc).split()) or "(no message)"
    text = f"{type(exc).__name__}: {text}"
    return text if len(text) <= limit else text[: limit - 3] + "..."


def execute(task: RunTask) -> RunOutcome:
    """Run one scan (in a worker process or inline); never raises for a failure of the run itself."""
    t0 = time.perf_counter()
    try:
        if task.threads is None:
            return _execute(task, t0)
        from threadpoolctl import threadpool_limits

        with threadpool_limits(limits=task.threads):
            return _execute(task, t0)
    except Exception as exc:  # one run's failure must not lose the others
        outcome = RunOutcome.failed(task, one_line(exc))
        outcome.seconds = time.perf_counter() - t0
        return outcome


def _execute(task: RunTask, t0: float) -> RunOutcome:
    from nbv.reachable import reachable_coverage
    from nbv.run import simulate

    scan = simulate(
        task.model,
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
    )
    outcome = RunOutcome(task.label, task.planner, task.seed, terminated=scan.result.terminated)
    for r in scan.result.records:
        outcome.rows.append(
            {
                "model": task.label,
                "planner": task.planner,
                "seed": task.seed,
                "iteration": r.index,
                "coverage": r.coverage,
                "points": r.points,
                "plan_seconds": r.plan_seconds,
                "eval_seconds": r.timings.get("score", 0.0),
                "fit_seconds": r.timings.get("cluster", 0.0) + r.timings.get("ellipsoids", 0.0),
                "robot_seconds": r.robot_seconds,
            }
        )
        outcome.poses.append(r.pose.to_dict())
    outcome.seconds = time.perf_counter() - t0
    if task.reachable:
        try:
            outcome.reachable_coverage = reachable_coverage(scan.cell, scan.planner, scan.surface_samples)
        except Exception as exc:  # the scan itself is still good
            outcome.reachable_error = one_line(exc)
    return outcome


# ---------------------------------------------------------------- running many


def run_tasks(tasks: Sequence[RunTask], jobs: int, done: Callable[[RunOutcome], None]) -> None:
    """Run ``tasks``, calling ``done`` in this process as each finishes.

    jobs == 1: inline, in order. Otherwise a process pool with ``jobs`` workers and one
    task per worker process, forked from a fork server that has imported :data:`PRELOAD`
    (where the platform has no fork server: spawned). If a worker dies (crash, out of memory),
    the runs that were lost with the pool are retried one at a time, so only the run
    that killed its process is reported as failed.
    """
    if jobs == 1:
        for task in tasks:
            done(execute(task))
        return
    for task in _pool_pass(tasks, jobs, done):
        if _pool_pass([task], 1, done):
            done(RunOutcome.failed(task, "the worker process died (a crash or out of memory)"))


def _pool_pass(tasks: Sequence[RunTask], jobs: int, done: Callable[[RunOutcome], None]) -> list[RunTask]:
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


# ---------------------------------------------------------------- the command


def add_arguments(parser: argparse.ArgumentParser) -> None:
    """The ``nbv bench`` options: the scan options of ``nbv scan`` plus models, planners, seeds, jobs, out."""
    parser.add_argument(
        "--models", nargs="+", required=True, metavar="MODEL", help="built-in object names and/or mesh files"
    )
    parser.add_argument(
        "--planners", default=DEFAULT_PLANNERS, help=f"comma-separated view evaluators (default {DEFAULT_PLANNERS})"
    )
    parser.add_argument("--seeds", type=int, default=1, help="runs per (model, planner): seeds --seed, --seed+1, ...")
    parser.add_argument("--jobs", type=int, default=2, help="worker processes (default 2; 1 runs inline)")
    parser.add_argument("--out", type=Path, default=Path("out/bench"), help="output directory (default out/bench)")
    parser.add_argument("--no-reachable", action="store_true", help="skip the reachable-coverage ceiling")
    add_scan_options(parser, model_required=False)


def parse_planners(text: str) -> list[str]:
    """Planner names from ``--planners``; CliError for an empty list, a duplicate or an unknown name."""
    from planner.evaluators import evaluator_names

    names = [n.strip() for n in text.split(",") if n.strip()]
    if not names:
        raise CliError("--planners: give at least one planner")
    known = evaluator_names()
    for i, name in enumerate(names):
        if name not in known:
            raise CliError(f"--planners: unknown planner {name!r} (known: {', '.join(known)})")
        if name in names[:i]:
            raise CliError(f"--planners: {name!r} is listed twice")
    return names


def resolve_models(specs: Sequence[str], up: str, size: float) -> list[tuple[str, str]]:
    """(spec, unique label) per model; loads each once so a bad file fails before any work starts."""
    from devices.builtins import resolve_model

    out: list[tuple[str, str]] = []
    labels: set[str] = set()
    for spec in specs:
        try:
            name, _ = resolve_model(spec, up=up, size=size)  # type: ignore[arg-type]
        except (ValueError, OSError) as exc:
            raise CliError(f"--models: {' '.join(str(exc).split())}") from None
        label, k = name, 2
        while label in labels:
            label, k = f"{name}-{k}", k + 1
        labels.add(label)
        out.append((spec, label))
    return out


def make_tasks(args: argparse.Namespace) -> list[RunTask]:
    """Validate the arguments and list the runs, the reachable-ceiling runs first; CliError on bad input."""
    if args.views is not None and args.views < 1:
        raise CliError(f"--views: must be >= 1, got {args.views}")
    if args.seeds < 1:
        raise CliError(f"--seeds: must be >= 1, got {args.seeds}")
    if args.jobs < 1:
        raise CliError(f"--jobs: must be >= 1, got {args.jobs}")
    if args.depth_noise < 0 or args.pose_noise < 0:
        raise CliError("--depth-noise and --pose-noise: must be >= 0")
    planners = parse_planners(args.planners)
    base = planner_config_from_args(args)
    models = resolve_models(args.models, args.up, args.size)
    ceiling = "projection" if "projection" in planners else planners[0]
    threads = None if args.jobs == 1 else max(1, (os.cpu_count() or 1) // args.jobs)
    tasks: list[RunTask] = []
    for spec, label in models:
        for seed in range(args.seed, args.seed + args.seeds):
            config = base.replace(cluster={"seed": seed})
            for name in planners:
                tasks.append(
                    RunTask(
                        spec,
                        label,
                        name,
                        seed,
                        config,
                        size=args.size,
                        up=args.up,
                        yaw_deg=args.yaw,
                        depth_noise=args.depth_noise,
                        pose_noise=args.pose_noise,
                        reachable=not args.no_reachable and name == ceiling,
                        threads=threads,
                        arm=args.arm,
                    )
                )
    tasks.sort(key=lambda t: not t.reachable)  # the slower runs start first
    return tasks


def run(args: argparse.Namespace) -> int:
    """The body of ``nbv bench``: 0 when every run succeeded, 1 when any failed (2 on bad input, via CliError)."""
    from rich.console import Console
    from rich.markup import escape
    from rich.progress import BarColumn, MofNCompleteColumn, Progress, TextColumn, TimeElapsedColumn

    from nbv import bench_report as report

    tasks = make_tasks(args)
    out: Path = args.out
    out.mkdir(parents=True, exist_ok=True)
    console = Console(highlight=False)
    outcomes: list[RunOutcome] = []
    t_start = time.perf_counter()
    columns = (TextColumn("{task.description}"), BarColumn(), MofNCompleteColumn(), TimeElapsedColumn())
    with Progress(*columns, console=console) as progress:
        bar = progress.add_task(f"bench: {len(tasks)} runs, {args.jobs} job(s)", total=len(tasks))

        def done(outcome: RunOutcome) -> None:
            outcomes.append(outcome)
            report.write_results(out, outcomes)
            progress.console.print(_describe(outcome), soft_wrap=True)
            progress.advance(bar)

        run_tasks(tasks, args.jobs, done)
    config = tasks[0].config
    meta = {
        "models": list(dict.fromkeys(t.label for t in tasks)),
        "planners": list(dict.fromkeys(t.planner for t in tasks)),
        "seeds": list(range(args.seed, args.seed + args.seeds)),
        "views": config.termination.max_views,
        "resolution": config.voxel.resolution,
        "candidates": config.candidates.count,
        "jobs": args.jobs,
        "threads": tasks[0].threads,
        "wall_seconds": time.perf_counter() - t_start,
    }
    report.write_report(out, outcomes, meta)
    console.print(f"wrote {out}/results.csv, runs.json, summary.md, coverage.png, time.png")
    problems = [o for o in outcomes if o.error or o.reachable_error]
    errors = Console(stderr=True, highlight=False)
    for o in problems:
        what = "run" if o.error is not None else "reachable coverage of"
        text = escape(o.error or o.reachable_error or "")
        errors.print(f"nbv bench: failed {what} {o.label} / {o.planner} / seed {o.seed}: {text}", soft_wrap=True)
    return 1 if problems else 0


def _describe(o: RunOutcome) -> str:
    """One rich-markup line about a finished run."""
    from rich.markup import escape

    head = escape(f"{o.label} / {o.planner} / seed {o.seed}")
    if o.error is not None:
        return f"[red]failed[/red] {head}: {escape(o.error)}"
    cov = o.rows[-1]["coverage"] if o.rows else None
    text = f"done {head}: {len(o.rows)} views, coverage {cov:.4f}" if cov is not None else f"done {head}"
    text += f", plan {sum(r['plan_seconds'] for r in o.rows):.2f} s, wall {o.seconds:.1f} s"
    if o.reachable_coverage is not None:
        text += f", reachable {o.reachable_coverage:.4f}"
    if o.reachable_error:
        text += f" [red](reachable coverage failed: {escape(o.reachable_error)})[/red]"
    return text


def load_runs(out: Path) -> list[dict[str, Any]]:
    """The runs.json entries of a finished bench (for tests and scripts)."""
    return json.loads((out / "runs.json").read_text())
