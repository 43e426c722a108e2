"""`make bench-agreement`: final coverage of the fast BIC search against the exhaustive sweep.

The goal: the fast search should leave final coverage within 1 point of the slow,
exhaustive configuration. One scan per model is a poor measure of that: the greedy
planner is chaotic, and any change to the ellipsoids (even between two equally good
mixtures) sends it down another path that ends up to 1.5 points higher or lower.
So every model is scanned in several placements (turned about the turntable axis by
``--yaws`` degrees, as ``nbv scan --yaw``) with each search, and the table compares the
mean final coverage per model, as well as the placement at yaw 0 on its own.

    python benchmarks/search_agreement.py [--models ../shared/models] [--out out/agreement]
        [--yaws 0,60,120,180,240,300] [--views 10] [--jobs 2] [--config planner.toml]

The scans are the library's bench runs (``workbench.evaluation.run_local``: the UR5 cell, ideal
sensor, no reachable-coverage ceiling, as ``nbv scan --no-reachable``), forked from one
preloaded process; each run's record (``RunOutcome.to_json`` with the model, the search and the
planner config) is written to ``OUT/<model>/yaw<deg>/<search>/run.json``.

The exhaustive runs are slow (5 to 10 s per view on a 2-core machine): the default
grid of 4 models x 6 placements x 2 searches took 16 minutes with 2 jobs.
"""

from __future__ import annotations

import argparse
import json
import statistics
from pathlib import Path

from planner.config import PlannerConfig
from workbench.evaluation import RunOutcome, RunTask, run_local

MODELS = ("bunny.obj", "armadillo.obj", "dragon.ply", "buddha.obj")
SEARCHES = ("fast", "exhaustive")
LIMIT = 0.01
"""Largest allowed |fast - exhaustive| in final coverage (1 point)."""


def main() -> int:
    p = argparse.ArgumentParser(description=(__doc__ or "").splitlines()[0])
    p.add_argument("--models", type=Path, default=Path("../shared/models"))
    p.add_argument("--out", type=Path, default=Path("out/agreement"))
    p.add_argument("--yaws", default="0,60,120,180,240,300", help="placements, degrees, comma-separated")
    p.add_argument("--views", type=int, default=10)
    p.add_argument("--jobs", type=int, default=2)
    p.add_argument("--config", type=Path, default=None, help="the planner config the scans start from (TOML)")
    p.add_argument("--only", default="", help="comma-separated model files")
    args = p.parse_args()
    yaws = [float(y) for y in args.yaws.split(",")]
    names = [n for n in MODELS if not args.only or n in args.only.split(",")]
    for name in names:
        if not (args.models / name).exists():
            raise SystemExit(f"missing model {args.models / name}")
    base = PlannerConfig.from_toml(args.config) if args.config else PlannerConfig()
    tasks = {
        (name, yaw, search): RunTask(
            str(args.models / name),
            f"{name}|{search}",  # the label keys a run: a model's two searches are two labels
            "projection",
            0,
            base.replace(termination={"max_views": args.views}, cluster={"search": search}),
            yaw_deg=yaw,
            threads=1 if args.jobs > 1 else None,
        )
        for name in names
        for yaw in yaws
        for search in SEARCHES
    }
    coverage: dict[tuple[str, float, str], float] = {}

    def done(outcome: RunOutcome) -> None:
        name, search = outcome.label.split("|")
        if outcome.error is not None or not outcome.rows:
            raise SystemExit(f"{name} yaw {outcome.yaw:g} {search}: the scan failed: {outcome.error}")
        key = (name, outcome.yaw, search)
        record = {**outcome.to_json(), "model": name, "search": search, "config": tasks[key].config.to_dict()}
        out = args.out / Path(name).stem / f"yaw{outcome.yaw:g}" / search
        out.mkdir(parents=True, exist_ok=True)
        (out / "run.json").write_text(json.dumps(record, indent=2))
        coverage[key] = float(record["final_coverage"])
        print(f"  {name:<14} yaw {outcome.yaw:>5g}  {search:<10} {coverage[key]:.4f}", flush=True)

    print(f"{len(tasks)} scans, {args.jobs} at a time ...", flush=True)
    run_local(list(tasks.values()), max(1, args.jobs), done)

    print()
    first = f"yaw {yaws[0]:g} diff"
    print(
        f"{'model':<14}{'mean fast':>10}{'mean exhaustive':>16}{'diff':>8}{first:>12}{'worst diff':>12}  within 1 point"
    )
    summary: dict[str, dict] = {}
    for name in names:
        fast = [coverage[(name, y, "fast")] for y in yaws]
        slow = [coverage[(name, y, "exhaustive")] for y in yaws]
        diffs = [f - s for f, s in zip(fast, slow, strict=True)]
        mean_fast, mean_slow = statistics.mean(fast), statistics.mean(slow)
        mean_diff = mean_fast - mean_slow
        worst = max(diffs, key=abs)
        ok = abs(mean_diff) <= LIMIT
        summary[name] = {
            "yaws": yaws, "fast": fast, "exhaustive": slow, "mean_fast": mean_fast,
            "mean_exhaustive": mean_slow, "mean_diff": mean_diff, "diffs": diffs, "within_limit": ok,
        }  # fmt: skip
        print(
            f"{name:<14}{mean_fast:>10.4f}{mean_slow:>16.4f}{100 * mean_diff:>+8.2f}"
            f"{100 * diffs[0]:>+12.2f}{100 * worst:>+12.2f}  {'yes' if ok else 'NO'}"
        )
    fast_all = statistics.mean(c for (_, _, search), c in coverage.items() if search == "fast")
    slow_all = statistics.mean(c for (_, _, search), c in coverage.items() if search == "exhaustive")
    print(
        f"\nall placements: mean fast {fast_all:.4f}, mean exhaustive {slow_all:.4f} ({100 * (fast_all - slow_all):+.2f} points)"
    )
    args.out.mkdir(parents=True, exist_ok=True)
    (args.out / "agreement.json").write_text(json.dumps(summary, indent=2))
    return 0 if all(s["within_limit"] for s in summary.values()) else 1


if __name__ == "__main__":
    raise SystemExit(main())
