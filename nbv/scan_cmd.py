"""``nbv scan`` and ``nbv profile``: one simulated scan with a progress table and output files."""

from __future__ import annotations

import argparse
import json
import statistics
import time
from pathlib import Path
from typing import Any

from rich.console import Console
from rich.table import Table

from nbv.options import cell_config_from_args, planner_config_from_args, seed_of
from workbench.evaluation import (
    STAGES,
    TIME_THRESHOLDS,
    IterationRecord,
    SimScan,
    cumulative_seconds,
    final_accuracy,
    icp_rejections,
    simulate,
    time_to_reach,
)


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
    """The metrics.json document `nbv scan` writes (docs/cli.md)."""
    records = scan.result.records
    seconds = [r.robot_seconds for r in records]
    time_to: dict[str, float | None] = {f"time_to_{round(100 * t)}": None for t in TIME_THRESHOLDS}
    coverage = [r.coverage for r in records]
    if scan.reachable_coverage and records and all(c is not None for c in coverage):
        ceiling = scan.reachable_coverage
        ratios = [float(c) / ceiling for c in coverage if c is not None]
        moves = [
            [(f["t"], f["coverage"] / ceiling) for f in r.move_frames if f["coverage"] is not None] for r in records
        ]
        time_to = {f"time_to_{round(100 * t)}": time_to_reach(ratios, seconds, t, moves) for t in TIME_THRESHOLDS}
    return {
        "model": scan.model,
        "planner": planner_name,
        "config": scan.config.to_dict(),
        "reachable_coverage": scan.reachable_coverage,
        "arm": scan.cell.config.kinematics,
        "arm_model": None if scan.cell.config.kinematics == "reach_sphere" else scan.cell.config.arm.urdf,
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
        "cumulative_robot_seconds": cumulative_seconds(seconds),
        "move_capture_hz": scan.cell.config.move_capture_hz,
        **time_to,
    }


def stage_table(records: list[IterationRecord]) -> dict[str, dict[str, float]]:
    """Median and max seconds per stage (and for the whole plan)."""
    out: dict[str, dict[str, float]] = {}
    for stage in (*STAGES, "plan"):
        values = [r.plan_seconds if stage == "plan" else r.timings.get(stage, 0.0) for r in records]
        out[stage] = {"median": float(statistics.median(values)), "max": float(max(values))}
    return out


def fidelity(scan: SimScan, iterations: list[int], console: Console | None) -> list[dict[str, Any]]:
    """BIC gap per voxel of the chosen model against the exhaustive sklearn sweep."""
    from planner.clustering import bic_gap, bic_sweep, t_range

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
            gap = bic_gap(chosen, sweep, n)
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
    from devices.config import CameraConfig
    from devices.ply import write_ply
    from workbench.surface import SurfaceIntegrator, ViewSurfaces, export_bytes, surface_config_for

    config = planner_config_from_args(args)
    camera = CameraConfig(depth_noise_std=args.depth_noise, sensor=args.sensor, calibration=args.calibration)
    integrator = SurfaceIntegrator(surface_config_for(camera))
    per_view = ViewSurfaces(integrator)
    console = Console(highlight=False)
    out: Path = args.out
    out.mkdir(parents=True, exist_ok=True)

    def start(name: str) -> None:
        console.print(f"[bold]{name}[/bold]: {config.termination.max_views} views, planner {args.planner}")
        console.print(_header(), highlight=False)

    scan = simulate(
        args.model,
        config,
        planner_name=args.planner,
        size=args.size,
        up=args.up,
        yaw_deg=args.yaw,
        seed=seed_of(args),
        depth_noise=args.depth_noise,
        pose_noise=args.pose_noise,
        reachable=not args.no_reachable,
        keep_plans=profile and args.fidelity,
        on_start=start,
        on_iteration=lambda record, plan: console.print(_row(record), highlight=False),
        arm=None,
        cell=cell_config_from_args(args),
        turn_while_moving=args.turn_while_moving,
        on_frame=per_view.add,
        on_move_frame=integrator.integrate,
        sensor=args.sensor,
        calibration=args.calibration,
    )
    if scan.reachable_coverage is not None:
        console.print(f"reachable coverage {scan.reachable_coverage:.4f} ({scan.ceiling_seconds:.1f} s)")
    doc = metrics_json(scan, args.planner)
    surface, doc["surface"], fscores = per_view.scored(scan.mesh)
    for row, fscore in zip(doc["iterations"], fscores, strict=True):
        row["surface_fscore_5mm"] = fscore
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
