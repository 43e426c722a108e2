"""Scans under real sensors and calibration error: per sensor x calibration preset, on the UR5 cell.

Run: ``nice .venv/bin/python benchmarks/bench_sensors.py [--models all] [--seeds 2] [--views 10] [--jobs 2]
[--sensors ideal,realsense-d435,...] [--calibrations typical,...] [--presets ideal:none,realsense-d435:poor]
[--bunny-check] [--no-ceilings] [--out out/bench_sensors]``.

Each preset scans every model (default: the 17 development meshes, ``/work/shared/models`` and its ``extra/``)
with each seed, projection planner. Printed per preset (mean over runs, at the last view):

- aborted: runs that failed or stopped before ``--views`` for a reason other than the planner's own rule
  (``no_eligible_view`` after every eligible view was refused, or an error); refused moves and ICP rejections;
- recall@5mm (the coverage), precision@5mm, F@5mm, chamfer (mm) (``workbench.evaluation.accuracy``);
- views to 95 % of the object's reachable ceiling (the perfect camera's; N + 1 when never);
- plan time: median ``plan_seconds`` over every view of every run.

``<out>/sensors.json`` also keeps each run's final recall, precision and F@5mm (``per_run``, "model/seed").

``--bunny-check``: the issue's check, the bunny at 2 mm depth noise (ideal sensor), 10 views, UR5: the first
frame's plate points and B with the paper's fixed 2 mm band and with the band that follows the noise, and the
final B of the scan against the noiseless scan's. Results also go to ``<out>/sensors.json``.
"""

from __future__ import annotations

import argparse
import json
import statistics
import time
from pathlib import Path
from typing import Any

import numpy as np

from planner import PlannerConfig
from workbench.evaluation import THRESHOLDS, RunOutcome, RunTask, run_local, run_metrics

MODELS = Path("/work/shared/models")
PLANNER_STOPS = ("max_views", "no_frontier", "growth")


def development_meshes() -> list[Path]:
    files = sorted(p for p in MODELS.iterdir() if p.suffix in (".obj", ".ply", ".off"))
    files += sorted(p for p in (MODELS / "extra").iterdir() if p.suffix in (".obj", ".ply", ".off"))
    return files


def ceilings(models: list[Path], views: int, cache: Path) -> dict[str, float]:
    """model name -> reachable-coverage ceiling with the perfect camera on the UR5 cell (cached on disk)."""
    from devices.builtins import resolve_model
    from devices.config import CameraConfig, CellConfig
    from devices.sim import make_sim_cell
    from workbench.evaluation import cached_ceiling

    out: dict[str, float] = {}
    config = PlannerConfig().replace(termination={"max_views": views})
    for path in models:
        _, mesh = resolve_model(str(path), up="y", size=0.2)
        cell = make_sim_cell(mesh, CameraConfig(), CellConfig())
        out[path.stem] = cached_ceiling(mesh, cell, CameraConfig(), config, cache).coverage
    return out


def summarise(outcomes: list[RunOutcome], ceiling: dict[str, float], views: int) -> dict[str, Any]:
    """The preset's figures (see the module docstring)."""
    aborted = [o for o in outcomes if o.error is not None or o.terminated not in PLANNER_STOPS]
    done = [o for o in outcomes if o.error is None and o.rows]

    def final(key: str) -> float | None:
        values = [float(o.rows[-1][key]) for o in done if o.rows[-1].get(key) is not None]
        return statistics.fmean(values) if values else None

    v95 = []
    for o in done:
        cov = [float(r["coverage"]) for r in o.rows if r["coverage"] is not None]
        if cov and ceiling.get(o.label):
            v95.append(run_metrics(cov, ceiling[o.label], views).views_to[THRESHOLDS.index(0.95)])
    plan = [float(r["plan_seconds"]) for o in done for r in o.rows]
    return {
        "runs": len(outcomes),
        "aborted": len(aborted),
        "aborted_runs": [f"{o.label}/{o.seed}: {o.error or o.terminated}" for o in aborted],
        "refused_moves": sum(len(o.refused_moves) for o in outcomes),
        "icp_rejected": sum(len(o.icp_rejected) for o in outcomes),
        "recall_5mm": final("recall_5mm"),
        "precision_5mm": final("precision_5mm"),
        "fscore_5mm": final("fscore_5mm"),
        "precision_2mm": final("precision_2mm"),
        "fscore_2mm": final("fscore_2mm"),
        "chamfer_mm": final("chamfer_mm"),
        "views_to_95": statistics.fmean(v95) if v95 else None,
        "plan_seconds_median": statistics.median(plan) if plan else None,
        "per_run": {
            f"{o.label}/{o.seed}": {k: o.rows[-1].get(k) for k in ("recall_5mm", "precision_5mm", "fscore_5mm")}
            for o in done
        },
    }


def bunny_check(views: int) -> dict[str, Any]:
    """The issue's check (see the module docstring)."""
    from devices.builtins import resolve_model
    from devices.config import CameraConfig, CellConfig
    from devices.planner_noise import planner_config_for
    from devices.sim import make_sim_cell
    from planner import Planner
    from workbench.evaluation import simulate

    bunny = str(MODELS / "bunny.obj")
    _, mesh = resolve_model(bunny, up="y", size=0.2)
    out: dict[str, Any] = {}
    for label, tuned in (("first frame, fixed 2 mm band", False), ("first frame, band follows the noise", True)):
        camera = CameraConfig(depth_noise_std=0.002)
        cell = make_sim_cell(mesh, camera, CellConfig(), seed=0)
        planner = Planner(planner_config_for(PlannerConfig(), camera) if tuned else PlannerConfig())
        planner.integrate(cell.capture())
        box = planner.voxel_map.bbox
        assert box is not None
        out[label] = {
            "cloud": len(planner.cloud),
            "plate_points": int(np.count_nonzero(planner.cloud[:, 2] < 0.003)),
            "B": [box.lower.round(3).tolist(), box.upper.round(3).tolist()],
        }
    config = PlannerConfig().replace(termination={"max_views": views})
    boxes = {}
    for label, noise in (("scan, noiseless", 0.0), ("scan, 2 mm depth noise", 0.002)):
        scan = simulate(bunny, config, depth_noise=noise, reachable=False)
        box = scan.planner.voxel_map.bbox
        assert box is not None
        boxes[label] = box
        out[label] = {
            "views": len(scan.result.records),
            "terminated": scan.result.terminated,
            "refused_moves": len(scan.result.refused_moves),
            "B": [box.lower.round(3).tolist(), box.upper.round(3).tolist()],
            "recall_5mm": scan.result.records[-1].coverage,
            "precision_5mm": (scan.result.records[-1].accuracy or {}).get("precision_5mm"),
        }
    a, b = boxes["scan, noiseless"], boxes["scan, 2 mm depth noise"]
    out["B difference, m"] = float(max(np.abs(a.lower - b.lower).max(), np.abs(a.upper - b.upper).max()))
    return out


def main() -> None:
    p = argparse.ArgumentParser(description=(__doc__ or "").split("\n", 1)[0])
    p.add_argument("--models", default="all", help="'all' (the 17 development meshes) or comma-separated paths")
    p.add_argument("--seeds", type=int, default=2)
    p.add_argument("--views", type=int, default=10)
    p.add_argument("--jobs", type=int, default=2)
    p.add_argument("--sensors", default="ideal,realsense-d435,realsense-d405,structured-light")
    p.add_argument("--calibrations", default="typical")
    p.add_argument("--presets", default="", help="extra sensor:calibration pairs, e.g. realsense-d435:poor")
    p.add_argument("--bunny-check", action="store_true")
    p.add_argument("--no-ceilings", action="store_true", help="skip the ceilings (views to 95 %% is then '-')")
    p.add_argument("--out", type=Path, default=Path("out/bench_sensors"))
    args = p.parse_args()
    args.out.mkdir(parents=True, exist_ok=True)
    report: dict[str, Any] = {}
    if args.bunny_check:
        t0 = time.perf_counter()
        report["bunny_check"] = bunny_check(args.views)
        print(json.dumps(report["bunny_check"], indent=1), f"({time.perf_counter() - t0:.0f} s)", flush=True)
    models = development_meshes() if args.models == "all" else [Path(m) for m in args.models.split(",") if m]
    presets = [(s, c) for s in args.sensors.split(",") if s for c in args.calibrations.split(",") if c]
    presets += [tuple(x.split(":", 1)) for x in args.presets.split(",") if x]  # type: ignore[misc]
    t0 = time.perf_counter()
    ceiling = {} if args.no_ceilings else ceilings(models, args.views, args.out / "ceilings")
    print(f"ceilings of {len(models)} models: {time.perf_counter() - t0:.0f} s", flush=True)
    config = PlannerConfig().replace(termination={"max_views": args.views})
    header = (
        f"{'sensor':18} {'calib':8} {'runs':>4} {'abort':>5} {'refused':>7} {'icp rej':>7} {'recall':>7} "
        f"{'prec@5':>7} {'F@5':>7} {'prec@2':>7} {'F@2':>7} {'chamf':>6} {'v95':>5} {'plan s':>6} {'wall s':>6}"
    )
    print(header, flush=True)
    for sensor, calibration in presets:
        tasks = [
            RunTask(
                str(path),
                path.stem,
                "projection",
                seed,
                config.replace(cluster={"seed": seed}),
                sensor=sensor,
                calibration=calibration,
                threads=1,
            )
            for path in models
            for seed in range(args.seeds)
        ]
        outcomes: list[RunOutcome] = []
        t0 = time.perf_counter()
        run_local(tasks, args.jobs, outcomes.append)
        s = summarise(outcomes, ceiling, args.views)
        s["wall_seconds"] = time.perf_counter() - t0
        report[f"{sensor}:{calibration}"] = s

        def f(key: str, digits: int = 4, width: int = 7, s: dict[str, Any] = s) -> str:
            v = s[key]
            return f"{'-':>{width}}" if v is None else f"{v:>{width}.{digits}f}"

        print(
            f"{sensor:18} {calibration:8} {s['runs']:>4} {s['aborted']:>5} {s['refused_moves']:>7} "
            f"{s['icp_rejected']:>7} {f('recall_5mm')} {f('precision_5mm')} {f('fscore_5mm')} {f('precision_2mm')} "
            f"{f('fscore_2mm')} {f('chamfer_mm', 2, 6)} {f('views_to_95', 2, 5)} {f('plan_seconds_median', 3, 6)} "
            f"{s['wall_seconds']:>6.0f}",
            flush=True,
        )
        for line in s["aborted_runs"]:
            print(f"    aborted: {line}", flush=True)
        (args.out / "sensors.json").write_text(json.dumps(report, indent=1))


if __name__ == "__main__":
    main()
