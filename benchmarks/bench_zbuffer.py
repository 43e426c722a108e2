"""Time the candidate-evaluation stage of projection, projection-zbuffer and raycast-apora on one scan state.

Run: ``PYTHONPATH=. .venv/bin/python benchmarks/bench_zbuffer.py --model ../shared/models/bunny.obj --views 3``.
The scan state is real: the mesh is scanned in the simulated cell for ``--views`` views (projection-zbuffer
choosing), then every evaluator scores the same 400 candidates of that state (the ellipsoid fit is done
once and excluded, as ``eval_seconds`` in ``nbv bench``). Prints the best of ``--repeats`` wall and CPU
times per evaluator and raster size, and the ratio to APORA. On a shared machine, read the CPU column.
"""

from __future__ import annotations

import argparse
import time
from collections.abc import Callable

import numpy as np

from planner.baselines.evaluators import AporaEvaluator
from planner.candidates import propose_candidates
from planner.config import PlannerConfig, ZBufferConfig
from planner.evaluators import EvaluationContext
from planner.scoring import score_views
from planner.visibility import score_visible_frontier
from workbench.evaluation import simulate


def best_of(fn: Callable[[], object], repeats: int) -> tuple[float, float]:
    """(wall, cpu) seconds, the best of ``repeats`` calls each."""
    walls, cpus = [], []
    for _ in range(repeats):
        w0, c0 = time.perf_counter(), time.process_time()
        fn()
        walls.append(time.perf_counter() - w0)
        cpus.append(time.process_time() - c0)
    return min(walls), min(cpus)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__)
    parser.add_argument("--model", default="../shared/models/bunny.obj")
    parser.add_argument("--views", type=int, default=3, help="views taken before timing")
    parser.add_argument("--repeats", type=int, default=5)
    args = parser.parse_args()
    config = PlannerConfig().replace(termination={"max_views": args.views})
    scan = simulate(args.model, config, planner_name="projection-zbuffer", reachable=False)
    planner = scan.planner
    plan = planner.last_plan
    assert plan is not None and planner.intrinsics is not None
    ells, K, res = list(plan.ellipsoids), planner.intrinsics, config.voxel.resolution
    cands, _, _ = propose_candidates(planner.voxel_map.bbox, config.candidates, config.partitions)  # type: ignore[arg-type]
    mask = np.ones(len(cands), dtype=bool)
    n_f = sum(e.kind == "frontier" for e in ells)
    print(
        f"{scan.model}, after {planner.iteration} views: {len(ells)} ellipsoids ({n_f} frontier), {len(cands)} candidates"
    )
    rows: list[tuple[str, float, float]] = []
    rows.append(
        ("projection (paper F)", *best_of(lambda: score_views(ells, cands, K, config.scoring, mask), args.repeats))
    )
    for w, h in ((40, 30), (80, 60)):
        zc = ZBufferConfig(width=w, height=h)
        rows.append(
            (
                f"projection-zbuffer {w}x{h}",
                *best_of(lambda zc=zc: score_visible_frontier(ells, cands, K, zc, mask, res), args.repeats),
            )
        )
    apora = AporaEvaluator(config)
    ctx = EvaluationContext(planner.voxel_map, cands, K, mask, np.random.default_rng(0))
    rows.append(("raycast-apora", *best_of(lambda: apora.evaluate(ctx), max(1, args.repeats // 2))))
    apora_cpu = rows[-1][2]
    print(f"{'evaluator':28} {'wall ms':>9} {'cpu ms':>9} {'APORA / this (cpu)':>20}")
    for name, wall, cpu in rows:
        print(f"{name:28} {1e3 * wall:9.1f} {1e3 * cpu:9.1f} {apora_cpu / cpu:20.0f}")


if __name__ == "__main__":
    main()
