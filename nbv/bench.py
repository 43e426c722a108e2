"""compare planners on several models in the simulated cell (results.csv, summary.md, report.html, plots)

``nbv bench --models l-block mug --planners projection,raycast-apora,random --seeds 2 --yaws 0,90``
runs every (model, placement, seed, planner) combination as one simulated scan
(:func:`nbv.scan_cmd.simulate`) on an executor (:mod:`workbench.evaluation.executors`: ``--executor local`` with
``--jobs`` worker processes, or ``--executor dask`` on a Dask cluster) and writes

- ``DIR/results.csv``: one row per (model, planner, seed, yaw, iteration), rewritten as runs complete;
- ``DIR/runs.json``: one entry per run (poses, stop reason, wall time, error);
- ``DIR/summary.md``, ``DIR/report.html``, ``DIR/ratio.png``, ``DIR/coverage.png``, ``DIR/time.png``:
  see :mod:`nbv.bench_report`.

The reachable-coverage ceiling belongs to the object and its placement, not to a run: it is
computed once per (model, yaw) before the runs (:func:`workbench.evaluation.object_ceiling.cached_ceiling`,
about a second; cached on disk under ``--ceiling-cache``) and shared by every planner and seed.

Fairness: every planner of a (model, placement, seed) gets the same cell, the same first view
(``Cell.initial_pose``), the same seed for camera noise, surface samples and the planner's random
choices. A failed run does not stop the others: its one-line error is reported and the exit code is 1.
"""

from __future__ import annotations

import argparse
import math
import os
import time
from collections.abc import Sequence
from pathlib import Path
from typing import Any

from nbv.options import CliError, add_scan_options, cell_config_from_args, planner_config_from_args, seed_of
from workbench.evaluation import MeshPayload, RunOutcome, RunTask, execute, one_line, run_dask, run_local

DEFAULT_PLANNERS = "projection,raycast-apora,raycast-oa,random"
DEFAULT_CEILING_CACHE = Path(os.environ.get("XDG_CACHE_HOME", Path.home() / ".cache")) / "nbv" / "ceilings"
"""Where ceilings are cached between benches (``--ceiling-cache``)."""

run_tasks = run_local  # the name earlier callers used
__all__ = ["RunOutcome", "RunTask", "add_arguments", "execute", "make_tasks", "one_line", "run", "run_tasks"]


# ---------------------------------------------------------------- the command


def add_arguments(parser: argparse.ArgumentParser) -> None:
    """The ``nbv bench`` options: the scan options of ``nbv scan`` plus models, planners, seeds, jobs, out."""
    parser.add_argument(
        "--models", nargs="+", default=None, metavar="MODEL", help="built-in object names and/or mesh files"
    )
    parser.add_argument(
        "--recorded",
        type=Path,
        default=None,
        metavar="DIR",
        help="instead of --models: a recorded view set (views.json folder or Stanford range scans); the planners "
        "(and 'oracle') choose among its views (docs/real-data.md)",
    )
    parser.add_argument(
        "--recorded-mesh",
        type=Path,
        default=None,
        metavar="MESH",
        help="with --recorded: the reference mesh in the set's frame (default: the set's own; without one the union "
        "of the views is the truth)",
    )
    parser.add_argument(
        "--planners", default=DEFAULT_PLANNERS, help="comma-separated view evaluators (default %(default)s)"
    )
    parser.add_argument(
        "--arms",
        default=None,
        help="comma-separated arms to sweep like planners (presets or URDF files, e.g. ur5,panda,xarm7): every run "
        "once per arm, the planner column reads planner@arm, results.csv's arm column names it (default: --arm)",
    )
    parser.add_argument("--seeds", type=int, default=1, help="runs per (model, planner): seeds --seed, --seed+1, ...")
    parser.add_argument(
        "--yaws",
        default=None,
        help="comma-separated placements: the object's turn about the turntable axis, degrees (default: --yaw)",
    )
    parser.add_argument(
        "--reference",
        default=None,
        help="the planner every other is compared with (default projection, or the first planner without it)",
    )
    parser.add_argument("--executor", choices=["local", "dask"], default="local", help="where runs execute")
    parser.add_argument(
        "--jobs", type=int, default=2, help="local: worker processes (default %(default)s; 1 runs inline)"
    )
    parser.add_argument("--address", default=None, help="dask: scheduler address (default: start a LocalCluster)")
    parser.add_argument(
        "--workers", type=int, default=2, help="dask: LocalCluster worker processes (default %(default)s)"
    )
    parser.add_argument("--out", type=Path, default=Path("out/bench"), help="output directory (default %(default)s)")
    parser.add_argument("--no-reachable", action="store_true", help="skip the reachable-coverage ceiling")
    parser.add_argument(
        "--ceiling-cache",
        type=Path,
        default=DEFAULT_CEILING_CACHE,
        help="directory of cached ceilings (default %(default)s)",
    )
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


def parse_arms(text: str | None) -> list[str]:
    """Arm names from ``--arms`` ([] when not given); CliError for an empty list, a duplicate or an unknown arm."""
    if text is None:
        return []
    from nbv.options import arm_name

    names = [n.strip() for n in text.split(",") if n.strip()]
    if not names:
        raise CliError("--arms: give at least one arm")
    for i, name in enumerate(names):
        try:
            arm_name(name)
        except argparse.ArgumentTypeError as exc:
            raise CliError(f"--arms: {exc}") from None
        if name in names[:i]:
            raise CliError(f"--arms: {name!r} is listed twice")
    return names


def run_planners(planners: Sequence[str], arms: Sequence[str]) -> list[str]:
    """The planners' names in the outputs: ``planner@arm`` for every arm of a sweep, else the planners."""
    return [f"{p}@{a}" for a in arms for p in planners] if arms else list(planners)


def resolve_models(specs: Sequence[str], up: str, size: float) -> list[tuple[str, str, Any]]:
    """(spec, unique label, placed mesh) per model; loads each once so a bad file fails before any work starts."""
    from devices.builtins import resolve_model

    out: list[tuple[str, str, Any]] = []
    labels: set[str] = set()
    for spec in specs:
        try:
            name, mesh = resolve_model(spec, up=up, size=size)  # type: ignore[arg-type]
        except (ValueError, OSError) as exc:
            raise CliError(f"--models: {' '.join(str(exc).split())}") from None
        label, k = name, 2
        while label in labels:
            label, k = f"{name}-{k}", k + 1
        labels.add(label)
        out.append((spec, label, mesh))
    return out


def parse_yaws(text: str | None, default: float) -> list[float]:
    """Placements from ``--yaws`` (comma-separated degrees); ``[default]`` when not given."""
    if text is None:
        return [float(default)]
    try:
        yaws = [float(v) for v in text.split(",") if v.strip()]
    except ValueError:
        raise CliError(f"--yaws: expected comma-separated degrees, got {text!r}") from None
    if not yaws:
        raise CliError("--yaws: give at least one angle")
    for i, y in enumerate(yaws):
        if not math.isfinite(y):
            raise CliError(f"--yaws: must be finite, got {y!r}")
        if y in yaws[:i]:
            raise CliError(f"--yaws: {y:g} is listed twice")
    return yaws


def check_args(args: argparse.Namespace) -> tuple[list[str], list[float]]:
    """(planners, yaws) after validating every option; CliError on bad input (before any work)."""
    views = getattr(args, "termination.max_views", None)
    if views is not None and views < 1:
        raise CliError(f"--views: must be >= 1, got {views}")
    if args.seeds < 1:
        raise CliError(f"--seeds: must be >= 1, got {args.seeds}")
    if args.jobs < 1:
        raise CliError(f"--jobs: must be >= 1, got {args.jobs}")
    if args.workers < 1:
        raise CliError(f"--workers: must be >= 1, got {args.workers}")
    if args.address is not None and args.executor != "dask":
        raise CliError("--address: only with --executor dask")
    if args.depth_noise < 0 or args.pose_noise < 0:
        raise CliError("--depth-noise and --pose-noise: must be >= 0")
    planners = parse_planners(args.planners)
    if parse_arms(getattr(args, "arms", None)) and args.arm is not None:
        raise CliError("--arms: give either --arm or --arms")
    if args.reference is not None and args.reference not in planners:
        raise CliError(f"--reference: {args.reference!r} is not among --planners ({', '.join(planners)})")
    return planners, parse_yaws(args.yaws, args.yaw)


def reference_of(args: argparse.Namespace, planners: Sequence[str]) -> str:
    """The planner others are compared with: ``--reference``, else projection when it takes part, else the first."""
    if args.reference is not None:
        return args.reference
    return "projection" if "projection" in planners else planners[0]


def make_tasks(args: argparse.Namespace, models: Sequence[tuple[str, str, Any]] | None = None) -> list[RunTask]:
    """Validate the arguments and list the runs; CliError on bad input."""
    planners, yaws = check_args(args)
    base = planner_config_from_args(args)
    cell = cell_config_from_args(args)
    arms = parse_arms(getattr(args, "arms", None))
    if models is None:
        models = resolve_models(args.models, args.up, args.size)
    parallel = args.workers if args.executor == "dask" else args.jobs
    threads = None if parallel == 1 and args.executor == "local" else max(1, (os.cpu_count() or 1) // parallel)
    tasks: list[RunTask] = []
    for spec, label, _ in models:
        for yaw in yaws:
            for seed in range(seed_of(args), seed_of(args) + args.seeds):
                config = base.replace(cluster={"seed": seed})
                for arm, name in [(a, p) for a in (arms or [None]) for p in planners]:
                    tasks.append(
                        RunTask(
                            spec,
                            label,
                            name,
                            seed,
                            config,
                            size=args.size,
                            up=args.up,
                            yaw_deg=yaw,
                            depth_noise=args.depth_noise,
                            pose_noise=args.pose_noise,
                            threads=threads,
                            arm=arm,
                            cell=cell,
                            arm_label=arm or "",
                            turn_while_moving=args.turn_while_moving,
                            sensor=args.sensor,
                            calibration=args.calibration,
                        )
                    )
    return tasks


def compute_ceilings(
    models: Sequence[tuple[str, str, Any]], yaws: Sequence[float], args: argparse.Namespace, say: Any
) -> tuple[dict[tuple[str, float], float], list[str]]:
    """((label, yaw) -> ceiling, one-line errors): one ceiling per model and placement, shared by all runs."""
    from devices.config import CameraConfig, cell_with_arm
    from devices.mesh import turned_about_plate_axis
    from devices.sim import make_sim_cell
    from workbench.evaluation import cached_ceiling

    config = planner_config_from_args(args)
    camera = CameraConfig()
    out: dict[tuple[str, float], float] = {}
    errors: list[str] = []
    cell_config = cell_config_from_args(args)
    arms: list[str | None] = list(parse_arms(getattr(args, "arms", None))) or [None]
    for _, model_label, mesh in models:
        for arm in arms:
            label = model_label if arm is None else f"{model_label}@{arm}"
            for yaw in yaws:
                try:
                    placed = turned_about_plate_axis(mesh, yaw) if yaw % 360.0 != 0.0 else mesh
                    cell = make_sim_cell(placed, camera, cell_with_arm(cell_config, arm))
                    ceiling = cached_ceiling(placed, cell, camera, config, args.ceiling_cache)
                except Exception as exc:  # the runs are still worth doing
                    errors.append(f"ceiling of {label} / yaw {yaw:g}: {one_line(exc)}")
                    continue
                out[(label, yaw)] = ceiling.coverage
                how = "cached" if ceiling.cached else f"{ceiling.seconds:.2f} s"
                say(f"ceiling {label} / yaw {yaw:g}: {ceiling.coverage:.4f} ({ceiling.views} reachable views, {how})")
    return out, errors


def run(args: argparse.Namespace) -> int:
    """The body of ``nbv bench``: 0 when every run succeeded, 1 when any failed (2 on bad input, via CliError)."""
    if args.recorded is not None:
        from nbv.bench_recorded import run_recorded_bench

        return run_recorded_bench(args)
    if not args.models:
        raise CliError("--models: give at least one model (or --recorded DIR)")
    if args.recorded_mesh is not None:
        raise CliError("--recorded-mesh: only with --recorded")
    from rich.console import Console
    from rich.markup import escape
    from rich.progress import BarColumn, MofNCompleteColumn, Progress, TextColumn, TimeElapsedColumn

    from nbv import bench_report as report

    planners, yaws = check_args(args)
    arms = parse_arms(getattr(args, "arms", None))
    models = resolve_models(args.models, args.up, args.size)
    tasks = make_tasks(args, models)
    out: Path = args.out
    out.mkdir(parents=True, exist_ok=True)
    console = Console(highlight=False)
    t_start = time.perf_counter()
    ceilings: dict[tuple[str, float], float] = {}
    problems: list[str] = []
    if not args.no_reachable:
        ceilings, problems = compute_ceilings(models, yaws, args, console.print)
    ceiling_seconds = time.perf_counter() - t_start
    views = tasks[0].config.termination.max_views
    outcomes: list[RunOutcome] = []
    where = f"dask ({args.address or f'LocalCluster, {args.workers} workers'})" if args.executor == "dask" else None
    where = where or f"{args.jobs} job(s)"
    columns = (TextColumn("{task.description}"), BarColumn(), MofNCompleteColumn(), TimeElapsedColumn())
    t_runs = time.perf_counter()
    with Progress(*columns, console=console) as progress:
        bar = progress.add_task(f"bench: {len(tasks)} runs, {where}", total=len(tasks))

        def done(outcome: RunOutcome) -> None:
            outcomes.append(outcome)
            report.write_results(out, outcomes, ceilings, views)
            progress.console.print(_describe(outcome, ceilings), soft_wrap=True)
            progress.advance(bar)

        if args.executor == "dask":
            meshes = {label: MeshPayload.of(mesh) for _, label, mesh in models}
            try:
                run_dask(tasks, meshes, done, address=args.address, workers=args.workers)
            except OSError as exc:  # cannot reach the scheduler
                raise CliError(f"--address: {one_line(exc)}") from None
        else:
            run_local(tasks, args.jobs, done)
    config = tasks[0].config
    meta = {
        "models": [label for _, label, _ in models],
        "planners": run_planners(planners, arms),
        "reference": run_planners([reference_of(args, planners)], arms[:1])[0],
        "arms": arms,
        "seeds": list(range(seed_of(args), seed_of(args) + args.seeds)),
        "yaws": yaws,
        "views": views,
        "resolution": config.voxel.resolution,
        "candidates": config.candidates.count,
        "executor": where,
        "jobs": args.jobs,
        "threads": tasks[0].threads,
        "wall_seconds": time.perf_counter() - t_start,
        "runs_seconds": time.perf_counter() - t_runs,
        "ceiling_seconds": ceiling_seconds,
    }
    report.write_report(out, outcomes, meta, ceilings)
    console.print(f"wrote {out}/results.csv, runs.json, summary.md, report.html and the plots")
    errors = Console(stderr=True, highlight=False)
    for text in problems:
        errors.print(f"nbv bench: failed {escape(text)}", soft_wrap=True)
    failed = [o for o in outcomes if o.error]
    for o in failed:
        head = f"{o.label} / {o.planner} / seed {o.seed}" + (f" / yaw {o.yaw:g}" if len(yaws) > 1 else "")
        errors.print(f"nbv bench: failed run {escape(head)}: {escape(o.error or '')}", soft_wrap=True)
    return 1 if failed or problems else 0


def _describe(o: RunOutcome, ceilings: dict[tuple[str, float], float]) -> str:
    """One rich-markup line about a finished run."""
    from rich.markup import escape

    head = escape(f"{o.label} / {o.planner} / seed {o.seed} / yaw {o.yaw:g}")
    if o.error is not None:
        return f"[red]failed[/red] {head}: {escape(o.error)}"
    cov = o.rows[-1]["coverage"] if o.rows else None
    text = f"done {head}: {len(o.rows)} views, coverage {cov:.4f}" if cov is not None else f"done {head}"
    ceiling = ceilings.get(o.ceiling_key)
    if cov is not None and ceiling:
        text += f" ({cov / ceiling:.1%} of the ceiling)"
    text += f", plan {sum(r['plan_seconds'] for r in o.rows):.2f} s, wall {o.seconds:.1f} s"
    return text
