"""`make bench`: `nbv profile` on the four shared models, one summary table.

Each model runs in its own process so its peak RSS can be reported.

    python benchmarks/profile_models.py [--models ../shared/models] [--out out/bench]
        [--fidelity] [--views 10] [--extra "--search exhaustive"]
"""

from __future__ import annotations

import argparse
import json
import resource
import shlex
import statistics
import subprocess
import sys
import time
from pathlib import Path

MODELS = ("bunny.obj", "armadillo.obj", "dragon.ply", "buddha.obj")


def run_one(model: Path, out: Path, args: argparse.Namespace) -> dict:
    cmd = [
        sys.executable, "-m", "nbv.cli", "profile", "--model", str(model), "--views", str(args.views),
        "--out", str(out), *shlex.split(args.extra),
    ]  # fmt: skip
    if args.fidelity:
        cmd.append("--fidelity")
    before = resource.getrusage(resource.RUSAGE_CHILDREN).ru_maxrss
    t0 = time.perf_counter()
    proc = subprocess.run(cmd, capture_output=not args.verbose, text=True)
    wall = time.perf_counter() - t0
    if proc.returncode != 0:
        raise SystemExit(f"{model.name}: nbv profile failed\n{proc.stderr if proc.stderr else ''}")
    prof = json.loads((out / "profile.json").read_text())
    metrics = json.loads((out / "metrics.json").read_text())
    prof["plan_seconds"] = [it["plan_seconds"] for it in metrics["iterations"]]
    peak = resource.getrusage(resource.RUSAGE_CHILDREN).ru_maxrss
    prof["peak_rss_mb"] = max(peak, before) / 1024.0
    prof["wall_seconds"] = wall
    return prof


def main() -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--models", type=Path, default=Path("../shared/models"))
    p.add_argument("--out", type=Path, default=Path("out/bench"))
    p.add_argument("--views", type=int, default=10)
    p.add_argument("--fidelity", action="store_true")
    p.add_argument("--extra", default="", help="more nbv profile flags, quoted")
    p.add_argument("--only", default="", help="comma-separated model files")
    p.add_argument("--verbose", action="store_true")
    args = p.parse_args()
    names = [n for n in MODELS if not args.only or n in args.only.split(",")]
    rows = []
    for name in names:
        path = args.models / name
        if not path.exists():
            raise SystemExit(f"missing model {path}")
        print(f"profiling {name} ...", flush=True)
        rows.append((name, run_one(path, args.out / Path(name).stem, args)))
    print()
    print(f"{'model':<14}{'median plan s':>14}{'max plan s':>12}{'worst BIC gap':>15}{'coverage':>10}"
          f"{'reachable':>11}{'peak RSS MB':>13}{'wall s':>8}")  # fmt: skip
    for name, r in rows:
        gap = r.get("bic_fidelity_worst")
        print(
            f"{name:<14}{r['median_plan_seconds']:>14.3f}{r['stages']['plan']['max']:>12.3f}"
            f"{(f'{gap:+.4f}' if gap is not None else '-'):>15}{r['final_coverage']:>10.4f}"
            f"{(r.get('reachable_coverage') or float('nan')):>11.4f}{r['peak_rss_mb']:>13.0f}{r['wall_seconds']:>8.1f}"
        )
    all_plan = [s for _, r in rows for s in r["plan_seconds"]]
    print(f"\nmedian plan_seconds over all {len(all_plan)} iterations: {statistics.median(all_plan):.3f} s")
    summary = {name: r for name, r in rows}
    args.out.mkdir(parents=True, exist_ok=True)
    (args.out / "summary.json").write_text(json.dumps(summary, indent=2))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
