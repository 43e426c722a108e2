"""``nbv scan`` and ``nbv profile``: one simulated scan with a progress table and output files."""

from __future__ import annotations

import argparse
import json
import math
import statistics
import time
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
from rich.console import Console
from rich.table import Table

from nbv.options import planner_config_from_args
from nbv.scan import STAGES, IterationRecord, ScanResult, run_scan
from planner import DepthFrame, Planner, PlannerConfig, PlanResult
from workbench.evaluation import ACCURACY_COLUMNS


@dataclass
class SimScan:
    """A finished simulated scan with what is needed to report on it."""

    model: str
    config: PlannerConfig
    result: ScanResult
    planner: Planner
    reachable_coverage: float | None
    surface_samples: np.ndarray
    cell: Any
    mesh: Any = None
    """The placed (and turned) ground-truth mesh in the table frame."""


def simulate(
    model: str,
    config: PlannerConfig,
    *,
    planner_name: str = "projection",
    size: float = 0.2,
    up: str = "y",
    yaw_deg: float = 0.0,
    seed: int = 0,
    depth_noise: float = 0.0,
    pose_noise: float = 0.0,
    reachable: bool = True,
    keep_plans: bool = False,
    console: Console | None = None,
    mesh: Any = None,
    arm: str = "urdf",
    on_frame: Callable[[DepthFrame], None] | None = None,
    sensor: str = "ideal",
    calibration: str = "none",
) -> SimScan:
    """Load ``model``, build the simulated cell, run Algorithm 1, measure coverage.

    ``yaw_deg`` turns the placed object about the turntable axis (z through the plate
    centre) before the scan: the same object, set down another way round. ``mesh``: the
    placed mesh already loaded (then ``model`` is only its name; ``up`` and ``size`` are not
    applied again). ``reachable``: also compute the reachable-coverage ceiling of the object
    and placement (:func:`workbench.object_ceiling.object_ceiling`, independent of the run).
    ``arm``: 'urdf' (the UR5 with IK, collision checks and joint trajectories) or 'reach_sphere'
    (``CellConfig.kinematics``). ``on_frame``: hears each frame with its registered pose (``run_scan``).
    ``sensor``, ``calibration``: the camera's sensor model and the cell's
    calibration error by name (``CameraConfig.sensor`` / ``.calibration``); the planner's noise settings
    follow them (``devices.planner_noise.planner_config_for``). Accuracy per view against the mesh is in
    ``IterationRecord.accuracy``.
    """
    from devices.builtins import resolve_model
    from devices.config import CameraConfig, CellConfig
    from devices.mesh import sample_surface, turned_about_plate_axis
    from devices.planner_noise import planner_config_for
    from devices.sim import make_sim_cell
    from workbench.evaluation import GroundTruth
    from workbench.object_ceiling import object_ceiling

    if not (math.isfinite(size) and size > 0):
        raise ValueError(f"--size: must be > 0, got {size}")
    if depth_noise < 0 or pose_noise < 0:
        raise ValueError("--depth-noise and --pose-noise must be >= 0")
    if not math.isfinite(yaw_deg):
        raise ValueError(f"--yaw: must be finite, got {yaw_deg}")
    if mesh is None:
        name, mesh = resolve_model(model, up=up, size=size)  # type: ignore[arg-type]
    else:
        name = model
    if yaw_deg % 360.0 != 0.0:
        mesh = turned_about_plate_axis(mesh, yaw_deg)
    camera = CameraConfig(
        depth_noise_std=depth_noise, pose_noise_translation=pose_noise, sensor=sensor, calibration=calibration
    )
    config = planner_config_for(config, camera)
    if arm not in ("urdf", "reach_sphere"):
        raise ValueError(f"--arm: 'urdf' or 'reach_sphere', got {arm!r}")
    cell = make_sim_cell(mesh, camera, CellConfig(kinematics=arm), seed=seed)  # type: ignore[arg-type]
    samples = sample_surface(mesh, 10_000, seed=seed)
    planner = Planner(config, evaluator=planner_name)

    def show(record: IterationRecord, plan: PlanResult) -> None:
        if console is not None:
            console.print(_row(record), highlight=False)

    if console is not None:
        console.print(f"[bold]{name}[/bold]: {config.termination.max_views} views, planner {planner_name}")
        console.print(_header(), highlight=False)
    truth = GroundTruth.of(mesh, samples)
    result = run_scan(
        planner, cell, samples, on_iteration=show, keep_plans=keep_plans, on_frame=on_frame, truth=truth
    )
    ceiling = None
    if reachable:
        t0 = time.perf_counter()
        ceiling = object_ceiling(mesh, cell, CameraConfig(), config).coverage
        if console is not None:
            console.print(f"reachable coverage {ceiling:.4f} ({time.perf_counter() - t0:.1f} s)")
    return SimScan(name, config, result, planner, ceiling, samples, cell, mesh)


def _header() -> str:
    return f"{'view':>4} {'coverage':>8} {'points':>7} {'plan s':>7} {'T_o':>4} {'T_f':>4} {'n_o':>6} {'n_f':>6}  icp"


def _row(r: IterationRecord) -> str:
    cov = f"{r.coverage:.4f}" if r.coverage is not None else "-"
    icp = "-" if r.registration is None else ("ok" if r.registration["accepted"] else "rejected")
    return (
        f"{r.index:>4} {cov:>8} {r.points:>7} {r.plan_seconds:>7.3f} {r.t_occupied:>4} {r.t_frontier:>4}"
        f" {r.n_occupied:>6} {r.n_frontier:>6}  {icp}"
    )


def metrics_json(scan: SimScan, planner_name: str) -> dict[str, Any]:
    """The metrics.json document of issue 2."""
    records = scan.result.records
    return {
        "model": scan.model,
        "planner": planner_name,
        "config": scan.config.to_dict(),
        "reachable_coverage": scan.reachable_coverage,
        "arm": scan.cell.config.kinematics,
        "sensor": scan.cell.camera.config.sensor,
        "calibration": scan.cell.camera.config.calibration,
        "calibration_error": None if scan.cell.errors is None else scan.cell.errors.summary(),
        "iterations": [r.to_json() for r in records],
        "final_coverage": records[-1].coverage if records else 0.0,
        **final_accuracy(records),
        "refused_moves": scan.result.refused_moves,
        "icp_rejected": icp_rejections(records),
        "terminated": scan.result.terminated,
        "seconds": scan.result.seconds,
        "robot_seconds": scan.result.robot_seconds,
    }


def final_accuracy(records: list[IterationRecord]) -> dict[str, Any]:
    """The last view's :data:`ACCURACY_COLUMNS` (None each without a ground truth)."""
    acc = records[-1].accuracy if records else None
    return {k: None if acc is None else acc[k] for k in ACCURACY_COLUMNS}


def icp_rejections(records: list[IterationRecord]) -> list[dict[str, Any]]:
    """The views whose ICP result was rejected, and why (``view``, ``reason``)."""
    return [
        {"view": r.index, "reason": r.registration.get("reason")}
        for r in records
        if r.registration is not None and not r.registration.get("accepted", True)
    ]


def stage_table(records: list[IterationRecord]) -> dict[str, dict[str, float]]:
    """Median and max seconds per stage (and for the whole plan)."""
    out: dict[str, dict[str, float]] = {}
    for stage in (*STAGES, "plan"):
        values = [r.plan_seconds if stage == "plan" else r.timings.get(stage, 0.0) for r in records]
        out[stage] = {"median": float(statistics.median(values)), "max": float(max(values))}
    return out


def fidelity(scan: SimScan, iterations: list[int], console: Console | None) -> list[dict[str, Any]]:
    """BIC gap per voxel of the chosen model against the exhaustive sklearn sweep."""
    from planner.clustering import bic_sweep, t_range

    cfg = scan.config.cluster
    res = scan.config.voxel.resolution
    rows: list[dict[str, Any]] = []
    plans = {p.iteration: p for p in scan.result.plans}
    for it in iterations:
        plan = plans.get(it)
        if plan is None:
            continue
        for fit in plan.fits:
            points = plan.voxels.occupied if fit.kind == "occupied" else plan.voxels.frontier
            n = len(points)
            if n == 0 or fit.t_chosen == 0:
                continue
            chosen = dict(fit.bic)[fit.t_chosen]
            t_lo, t_hi = t_range(n, cfg)
            t0 = time.perf_counter()
            sweep = bic_sweep(points, range(t_lo, t_hi + 1), cfg, res)
            best_t = min(sweep, key=lambda t: sweep[t])
            gap = (chosen - sweep[best_t]) / n
            row = {
                "iteration": it,
                "kind": fit.kind,
                "n": n,
                "t_chosen": fit.t_chosen,
                "t_sweep": best_t,
                "gap_per_voxel": gap,
                "sweep_seconds": time.perf_counter() - t0,
            }
            rows.append(row)
            if console is not None:
                console.print(
                    f"fidelity it {it:>2} {fit.kind:9s} n={n:5d} T={fit.t_chosen:>2} sweep T={best_t:>2} "
                    f"gap/voxel={gap:+.4f} ({row['sweep_seconds']:.1f} s)",
                    highlight=False,
                )
    return rows


def print_stage_table(console: Console, stages: dict[str, dict[str, float]]) -> None:
    table = Table(title="plan time per stage (s)")
    table.add_column("stage")
    table.add_column("median", justify="right")
    table.add_column("max", justify="right")
    for stage, v in stages.items():
        table.add_row(stage, f"{v['median']:.4f}", f"{v['max']:.4f}")
    console.print(table)


def _surface_summary(block: dict[str, Any]) -> str:
    if "error" in block:
        return f"; no surface ({block['error']})"
    score = "" if block["fscore_5mm"] is None else f" F@5mm {block['fscore_5mm']:.4f}"
    return f"; surface{score}, {block['triangles']} triangles, {block['seconds']:.1f} s"


def run_and_report(args: argparse.Namespace, profile: bool) -> dict[str, Any]:
    """The body of ``nbv scan`` / ``nbv profile``; returns the JSON written."""
    from devices.ply import write_ply
    from workbench.surface import SurfaceIntegrator, export_bytes, surface_block

    config = planner_config_from_args(args)
    integrator = SurfaceIntegrator()
    console = Console(highlight=False)
    out: Path = args.out
    out.mkdir(parents=True, exist_ok=True)
    scan = simulate(
        args.model,
        config,
        planner_name=args.planner,
        size=args.size,
        up=args.up,
        yaw_deg=args.yaw,
        seed=args.seed,
        depth_noise=args.depth_noise,
        pose_noise=args.pose_noise,
        reachable=not args.no_reachable,
        keep_plans=profile and args.fidelity,
        console=console,
        arm=args.arm,
        on_frame=integrator.integrate,
        sensor=args.sensor,
        calibration=args.calibration,
    )
    doc = metrics_json(scan, args.planner)
    surface, doc["surface"] = surface_block(integrator, scan.mesh)
    (out / "metrics.json").write_text(json.dumps(doc, indent=2))
    write_ply(out / "cloud.ply", scan.planner.cloud)
    if surface is not None:
        (out / "surface.ply").write_bytes(export_bytes(surface, "ply"))
    records = scan.result.records
    stages = stage_table(records)
    plan_s = [r.plan_seconds for r in records]
    for rej in doc["icp_rejected"]:
        console.print(f"ICP rejected view {rej['view']}: {rej['reason']}")
    for ref in doc["refused_moves"]:
        console.print(f"move refused after view {ref['after_view']} (candidate {ref['candidate']}): {ref['message']}")
    console.print(
        f"final coverage {doc['final_coverage']:.4f}"
        + (
            f", precision@5mm {doc['precision_5mm']:.4f}, F@5mm {doc['fscore_5mm']:.4f}"
            if doc["precision_5mm"] is not None
            else ""
        )
        + (f" of reachable {scan.reachable_coverage:.4f}" if scan.reachable_coverage is not None else "")
        + _surface_summary(doc["surface"])
        + f"; median plan {statistics.median(plan_s):.3f} s, max {max(plan_s):.3f} s;"
        + f" robot time {scan.result.robot_seconds:.1f} s;"
        + f" stopped: {scan.result.terminated}; wrote {out}/metrics.json, {out}/cloud.ply"
        + ("" if surface is None else f", {out}/surface.ply")
    )
    if not profile:
        return doc
    print_stage_table(console, stages)
    worst = None
    rows: list[dict[str, Any]] = []
    if args.fidelity:
        its = [int(x) for x in str(args.fidelity_iterations).split(",") if x.strip()]
        rows = fidelity(scan, its, console)
        worst = max((r["gap_per_voxel"] for r in rows), default=None)
        console.print(f"worst BIC gap per voxel: {worst}")
    prof = {
        "model": scan.model,
        "median_plan_seconds": stages["plan"]["median"],
        "stages": stages,
        "bic_fidelity_worst": worst,
        "fidelity": rows,
        "final_coverage": doc["final_coverage"],
        "reachable_coverage": scan.reachable_coverage,
        "iterations": len(records),
    }
    (out / "profile.json").write_text(json.dumps(prof, indent=2))
    return prof
