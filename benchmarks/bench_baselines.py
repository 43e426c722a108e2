"""Time one candidate evaluation (400 candidates) of every baseline on a realistic voxel map.

The map is what the planner has after a few views of a shared model: the simulated
camera renders the mesh (plate included) from ``--views`` poses around it and
``Planner.integrate`` preprocesses, registers and integrates each frame. The
candidates are the planner's own (``propose_candidates`` on B, default config).
Each evaluator scores the same context ``--repeat`` times; the table gives the
fastest and the median of the evaluation's wall time (the sum of its
``Evaluation.timings``: "score" for the baselines; "cluster", "ellipsoids" and
"score" for projection), the fastest CPU time, and the per-part split of the
last ray-casting run.

    .venv/bin/python benchmarks/bench_baselines.py [--model ../shared/models/bunny.obj]
        [--views 3] [--repeat 3] [--planners projection,raycast-apora,raycast-oa,raycast-uv,raycast-rse,random]
"""

from __future__ import annotations

import argparse
import math
import statistics
import time
from pathlib import Path

import numpy as np

from planner import PlannerConfig, Pose
from planner.baselines import RaycastEvaluator
from planner.candidates import propose_candidates
from planner.evaluators import EvaluationContext, make_evaluator
from planner.planner import Planner
from planner.types import DepthFrame, VoxelClass

DEFAULT_PLANNERS = "projection,raycast-apora,raycast-oa,raycast-uv,raycast-rse,random"


def build_planner(model: Path, views: int, config: PlannerConfig) -> Planner:
    """A planner that has integrated ``views`` frames of ``model`` taken on a ring around it."""
    from devices.mesh import load_mesh
    from devices.sim import SimulatedCamera

    mesh = load_mesh(model, size=0.2)
    camera = SimulatedCamera(mesh)
    planner = Planner(config)
    target = np.array([0.0, 0.0, 0.08])
    for i in range(views):
        azimuth = 2.0 * math.pi * i / max(views, 1) * 0.6  # a partial sweep, as a scan in progress
        eye = target + np.array([0.45 * math.cos(azimuth), 0.45 * math.sin(azimuth), 0.25])
        pose = Pose.look_at(eye, target)
        planner.integrate(DepthFrame(camera.render(pose), pose, camera.intrinsics))
    return planner


def main() -> int:
    p = argparse.ArgumentParser(description=(__doc__ or "").splitlines()[0])
    p.add_argument("--model", type=Path, default=Path(__file__).resolve().parents[2] / "shared/models/bunny.obj")
    p.add_argument("--views", type=int, default=3, help="frames integrated before the timed evaluation")
    p.add_argument("--repeat", type=int, default=3)
    p.add_argument("--planners", default=DEFAULT_PLANNERS)
    args = p.parse_args()

    config = PlannerConfig()
    planner = build_planner(args.model, args.views, config)
    vm = planner.voxel_map
    assert vm.bbox is not None and planner.intrinsics is not None
    candidates, _, _ = propose_candidates(vm.bbox, config.candidates, config.partitions)
    ctx = EvaluationContext(
        vm, candidates, planner.intrinsics, np.ones(len(candidates), dtype=bool), np.random.default_rng(0)
    )
    counts = {c.name.lower(): vm.count(c) for c in VoxelClass}
    print(f"model {args.model.name}, {args.views} views: grid {vm.shape} = {int(np.prod(vm.shape))} voxels {counts}")
    print(f"{len(candidates)} candidates, intrinsics {planner.intrinsics.width}x{planner.intrinsics.height}\n")

    header = f"{'planner':<15} {'best s':>8} {'median s':>9} {'cpu s':>7} {'rays':>9} {'rays/view':>9}  parts (s)"
    print(header)
    print("-" * len(header))
    best: dict[str, float] = {}
    for name in args.planners.split(","):
        evaluator = make_evaluator(name, config)
        times, cpu = [], []
        for _ in range(args.repeat):
            evaluator.reset()
            c0 = time.process_time()
            evaluation = evaluator.evaluate(ctx)
            cpu.append(time.process_time() - c0)
            times.append(sum(evaluation.timings.values()))
        best[name] = min(times)
        rays, parts = "", ""
        if isinstance(evaluator, RaycastEvaluator):
            b = evaluator.last_breakdown
            n = int(b["n_rays"])
            rays = f"{n:>9} {n // len(candidates):>9}"
            parts = ", ".join(f"{k} {v:.3f}" for k, v in b.items() if not k.startswith("n_"))
            parts += f"; {b['n_visits'] / n:.1f} voxels/ray"
        elif name == "projection":
            parts = ", ".join(f"{k} {v:.3f}" for k, v in evaluation.timings.items())
        row = f"{name:<15} {min(times):>8.3f} {statistics.median(times):>9.3f} {min(cpu):>7.3f}"
        print(f"{row} {rays or '':>19}  {parts}")
    if "projection" in best:
        print()
        for name, t in best.items():
            if name != "projection" and name != "random":
                print(f"{name}: {t / best['projection']:.1f}x the projection evaluator's time")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
