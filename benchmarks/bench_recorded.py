"""Planners on the Stanford bunny's real range scans: each chooses among the ten recorded views.

Prints, per planner, views to 95 % of the recorded ceiling, the AUC of coverage / ceiling over the ten views and the
final F@5mm of the cloud and of the surface against bun_zipper.ply (random: mean and spread over 20 seeds), the
oracle's order and the fewest views that reach 95 % by brute force. Then the registration check: the recorded
poses perturbed by 3 mm / 1 degree, the cloud after ICP against the unperturbed run's.

    PYTHONPATH=$PWD .venv/bin/python benchmarks/bench_recorded.py [--data ../shared/real/stanford-bunny-scans]
        [--planners projection,projection-zbuffer,tour,raycast-apora,raycast-oa,raycast-uv,raycast-rse]
        [--random-seeds 20] [--no-surface]
"""

from __future__ import annotations

import argparse
import json
import statistics
import time
from pathlib import Path

import numpy as np
from scipy.spatial import KDTree
from scipy.spatial.transform import Rotation

from devices.recorded import read_recorded
from planner import Pose
from planner.config import PlannerConfig
from workbench.evaluation.recorded import (
    ORACLE,
    fewest_views,
    greedy_order,
    recorded_truth,
    run_recorded,
    view_cover,
)

PLANNERS = "projection,projection-zbuffer,tour,raycast-apora,raycast-oa,raycast-uv,raycast-rse"


def perturbation(seed: int, mm: float, deg: float):
    """A pose error per view: a random direction of ``mm`` millimetres and a random axis of ``deg`` degrees."""
    rng = np.random.default_rng(seed)

    def perturb(index: int, pose: Pose) -> Pose:
        if index == 0:
            return pose  # the first view anchors the world frame (ICP registers to the cloud so far)
        t = rng.normal(size=3)
        axis = rng.normal(size=3)
        R = Rotation.from_rotvec(np.radians(deg) * axis / np.linalg.norm(axis)).as_matrix()
        return Pose(R @ pose.rotation, pose.translation + mm / 1000 * t / np.linalg.norm(t))

    return perturb


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--data", default="../shared/real/stanford-bunny-scans")
    parser.add_argument("--planners", default=PLANNERS)
    parser.add_argument("--random-seeds", type=int, default=20)
    parser.add_argument("--no-surface", action="store_true")
    parser.add_argument("--out", type=Path, default=None, help="write the rows as JSON here")
    args = parser.parse_args()
    t0 = time.perf_counter()
    recorded = read_recorded(args.data)
    truth = recorded_truth(recorded)
    config = PlannerConfig()
    views = len(recorded.views)
    print(f"{recorded.name}: {views} views, read in {time.perf_counter() - t0:.1f} s")
    cover = view_cover(recorded, truth)
    print(
        "per view coverage of the truth (raw points, 5 mm):",
        ", ".join(f"{v.name} {c:.3f}" for v, c in zip(recorded.views, cover.mean(axis=1), strict=True)),
    )
    surface = not args.no_surface
    base = run_recorded(recorded, "recorded-order", config, truth, order=list(range(views)), surface=surface)
    ceiling = base.coverage[-1]
    print(
        f"recorded ceiling (all views through the pipeline): coverage {ceiling:.4f}, "
        f"F@5mm {base.fscore[-1]:.4f}, surface F@5mm {base.surface_fscore}"
    )
    best = fewest_views(cover)
    print(f"fewest views to 95 % of the raw union's coverage (brute force over subsets): {best}")
    rows = []
    oracle = run_recorded(recorded, ORACLE, config, truth, order=greedy_order(cover, first=0), surface=surface)
    rows.append(oracle.metrics(ceiling, views))
    for name in args.planners.split(","):
        t = time.perf_counter()
        run = run_recorded(recorded, name, config, truth, surface=surface)
        rows.append({**run.metrics(ceiling, views), "seconds": time.perf_counter() - t})
        print(name, f"{time.perf_counter() - t:.1f} s", flush=True)
    randoms = [
        run_recorded(recorded, "random", config, truth, seed=s, surface=surface).metrics(ceiling, views)
        for s in range(args.random_seeds)
    ]
    print("\n| planner | views to 95 % | AUC | final coverage | cloud F@5mm | surface F@5mm | order |")
    print("|---|---|---|---|---|---|---|")
    for r in rows:
        print(
            f"| {r['planner']} | {r['views_to_95']} | {r['auc']:.4f} | {r['final_coverage']:.4f} | "
            f"{r['final_fscore_5mm']:.4f} | {r['surface_fscore_5mm'] if r['surface_fscore_5mm'] is None else round(r['surface_fscore_5mm'], 4)} | {' '.join(r['order'])} |"
        )
    v95 = [r["views_to_95"] for r in randoms]
    auc = [r["auc"] for r in randoms]
    sf = [r["surface_fscore_5mm"] for r in randoms if r["surface_fscore_5mm"] is not None]
    print(
        f"| random (mean ± sd of {len(randoms)}) | {statistics.fmean(v95):.2f} ± {statistics.stdev(v95):.2f} | "
        f"{statistics.fmean(auc):.4f} ± {statistics.stdev(auc):.4f} | "
        f"{statistics.fmean(r['final_coverage'] for r in randoms):.4f} | "
        f"{statistics.fmean(r['final_fscore_5mm'] for r in randoms):.4f} | "
        f"{statistics.fmean(sf) if sf else float('nan'):.4f} | |"
    )
    # registration: perturbed recorded poses
    print("\nregistration, recorded order, poses perturbed per view (view 0 exact):")
    clean = run_recorded(recorded, "recorded-order", config, truth, order=list(range(views)), surface=False)
    for mm, deg in ((3.0, 1.0),):
        for s in range(3):
            run = run_recorded(
                recorded,
                "perturbed",
                config,
                truth,
                order=list(range(views)),
                surface=False,
                perturb=perturbation(s, mm, deg),
            )
            d = KDTree(clean.cloud).query(run.cloud)[0]
            errors = []
            for i in range(views):
                true = recorded.views[i].T_world_sensor
                got = run.poses[i]
                errors.append(np.linalg.norm(got.translation - true.translation) * 1000)
            print(
                f"  {mm} mm / {deg} deg seed {s}: cloud to unperturbed cloud RMS {1000 * np.sqrt(np.mean(d**2)):.3f} mm,"
                f" registered camera positions off by median {np.median(errors):.2f} mm (max {max(errors):.2f}),"
                f" F@5mm {run.fscore[-1]:.4f} (unperturbed {clean.fscore[-1]:.4f})"
            )
    if args.out is not None:
        args.out.write_text(json.dumps({"rows": rows, "random": randoms, "ceiling": ceiling}, indent=1))


if __name__ == "__main__":
    main()
