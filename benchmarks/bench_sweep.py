"""Sweep throughput (local pool vs Dask) and the reachable-coverage ceiling (time, agreement) per model.

Run from the project root::

    .venv/bin/python benchmarks/bench_sweep.py sweep [--views 5] [--seeds 2]
    .venv/bin/python benchmarks/bench_sweep.py ceiling [--models ../shared/models] [--extra] [--no-scan]

``sweep`` runs the same small grid (built-in l-block, mug, two-boxes x projection, random x
``--seeds`` seeds) with ``nbv bench --executor local --jobs 2`` and with ``--executor dask
--workers 2`` (a LocalCluster, started inside the timing) and prints scans per minute of each.
Ceilings are computed once, before the timings (the cache), so only the runs are compared.

``ceiling`` computes, per model (the four Stanford models; with ``--extra`` also the thirteen of
``models/extra``), the visibility ceiling (:func:`workbench.evaluation.object_ceiling.ceiling_mask`) and the
render-based reference on the same samples and views, and prints: reachable views, both ceilings,
the share of samples classified the same, the two wall times, and (unless ``--no-scan``) the
wall time of a 10-view projection scan of the model and the ceiling's share of it.
Budget: <= 2 s per model, <= 15 % of a 10-view scan, >= 99 % agreement.
The machine is shared: say under what load the numbers were taken.
"""

from __future__ import annotations

import argparse
import json
import os
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

from devices.builtins import resolve_model
from devices.config import CameraConfig, CellConfig
from devices.sim import make_sim_cell
from planner.config import PlannerConfig
from workbench.evaluation import DEFAULT_CEILING, ceiling_mask, reference_mask, simulate

GRID_MODELS = ["l-block", "mug", "two-boxes"]


def main_cli(args: list[str]) -> int:
    """Run the ``nbv`` command (the installed entry point beside this interpreter) as a user would."""
    return subprocess.run([str(Path(sys.executable).with_name("nbv")), *args], check=False).returncode


def sweep(views: int, seeds: int) -> dict[str, float]:
    common = ["--models", *GRID_MODELS, "--planners", "projection,random", "--seeds", str(seeds)]
    common += ["--views", str(views)]
    results: dict[str, float] = {}
    with tempfile.TemporaryDirectory() as tmp:
        cache = ["--ceiling-cache", str(Path(tmp) / "ceilings")]
        main_cli(["bench", *common, "--jobs", "1", "--views", "1", "--seeds", "1", "--out", f"{tmp}/warm", *cache])
        runs = len(GRID_MODELS) * 2 * seeds
        for name, extra in (
            ("local, 2 jobs", ["--executor", "local", "--jobs", "2"]),
            ("dask, 2 workers", ["--executor", "dask", "--workers", "2"]),
        ):
            t0 = time.perf_counter()
            code = main_cli(["bench", *common, *extra, "--out", f"{tmp}/{name.split(',')[0]}", *cache])
            wall = time.perf_counter() - t0
            results[name] = 60.0 * runs / wall
            print(f"{name:<16} {runs} scans in {wall:6.1f} s: {results[name]:.1f} scans per minute (exit {code})")
    return results


def ceiling_table(models: list[Path], scan: bool) -> list[dict[str, float | str]]:
    planner = PlannerConfig()
    camera = CameraConfig()
    rows: list[dict[str, float | str]] = []
    head = f"{'model':<18}{'faces':>8}{'views':>6}{'fast':>8}{'render':>8}{'agree':>8}{'fast s':>8}{'cpu s':>7}"
    head += f"{'render s':>9}"
    print(head + (f"{'scan s':>8}{'cpu s':>7}{'share':>7}" if scan else ""), flush=True)
    for path in models:
        name, mesh = resolve_model(str(path), up="y", size=0.2)
        cell = make_sim_cell(mesh, camera, CellConfig())
        t0, c0 = time.perf_counter(), time.process_time()
        fast, views = ceiling_mask(mesh, cell, camera, planner, DEFAULT_CEILING)
        fast_s, fast_cpu = time.perf_counter() - t0, time.process_time() - c0
        t0 = time.perf_counter()
        ref = reference_mask(mesh, cell, planner, DEFAULT_CEILING)
        ref_s = time.perf_counter() - t0
        row: dict[str, float | str] = {
            "model": name,
            "faces": len(mesh.faces),
            "views": views,
            "fast": float(fast.mean()),
            "render": float(ref.mean()),
            "agreement": float((fast == ref).mean()),
            "fast_seconds": fast_s,
            "fast_cpu_seconds": fast_cpu,
            "render_seconds": ref_s,
        }
        line = (
            f"{name:<18}{len(mesh.faces):>8}{views:>6}{fast.mean():>8.4f}{ref.mean():>8.4f}"
            f"{row['agreement']:>8.4f}{fast_s:>8.2f}{fast_cpu:>7.2f}{ref_s:>9.1f}"
        )
        if scan:
            t0, c0 = time.perf_counter(), time.process_time()
            simulate(str(path), planner, planner_name="projection", reachable=False)
            scan_s, scan_cpu = time.perf_counter() - t0, time.process_time() - c0
            row |= {"scan_seconds": scan_s, "scan_cpu_seconds": scan_cpu, "share_cpu": fast_cpu / scan_cpu}
            line += f"{scan_s:>8.1f}{scan_cpu:>7.1f}{fast_cpu / scan_cpu:>7.1%}"
        print(line, flush=True)
        rows.append(row)
    agree = [float(r["agreement"]) for r in rows]
    secs = [float(r["fast_seconds"]) for r in rows]
    cpu = [float(r["fast_cpu_seconds"]) for r in rows]
    print(
        f"agreement min {min(agree):.4f} mean {statistics.fmean(agree):.4f}; fast ceiling wall max {max(secs):.2f} s, "
        f"median {statistics.median(secs):.2f} s; CPU max {max(cpu):.2f} s, median {statistics.median(cpu):.2f} s"
    )
    return rows


def main() -> int:
    p = argparse.ArgumentParser(description=(__doc__ or "").splitlines()[0])
    sub = p.add_subparsers(dest="what", required=True)
    s = sub.add_parser("sweep")
    s.add_argument("--views", type=int, default=5)
    s.add_argument("--seeds", type=int, default=2)
    c = sub.add_parser("ceiling")
    c.add_argument("--models", type=Path, default=Path("../shared/models"))
    c.add_argument("--extra", action="store_true", help="also the thirteen meshes of MODELS/extra")
    c.add_argument("--no-scan", action="store_true", help="skip the 10-view scan per model")
    c.add_argument("--json", type=Path, default=None, help="also write the rows as JSON here")
    args = p.parse_args()
    print(f"load average {os.getloadavg()[0]:.1f} on {os.cpu_count()} CPUs", flush=True)
    if args.what == "sweep":
        sweep(args.views, args.seeds)
        return 0
    models = sorted(f for f in args.models.iterdir() if f.suffix in (".obj", ".ply", ".off"))
    if args.extra:
        models += sorted(f for f in (args.models / "extra").iterdir() if f.suffix in (".obj", ".ply", ".off"))
    rows = ceiling_table(models, scan=not args.no_scan)
    if args.json is not None:
        args.json.write_text(json.dumps(rows, indent=1))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
