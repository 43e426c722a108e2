"""Planners on the Stanford bunny's real range scans: each chooses among the ten recorded views.

Prints, per planner, views to 95 % of the recorded ceiling, the AUC of coverage / ceiling over the ten views and the
final F@5mm of the cloud and of the surface against bun_zipper.ply (random: mean and spread over 20 seeds), the
oracle's order and the fewest views that reach 95 % by brute force. Then the registration check: the recorded
poses perturbed by 3 mm / 1 degree, the cloud after ICP against the unperturbed run's, with the scanner's edge cells
kept, trimmed from the data, and trimmed for registration only.

    PYTHONPATH=$PWD .venv/bin/python benchmarks/bench_recorded.py [--data ../shared/real/stanford-bunny-scans]
        [--planners projection,projection-zbuffer,tour,raycast-apora,raycast-oa,raycast-uv,raycast-rse]
        [--random-seeds 20] [--no-surface]
"""

from __future__ import annotations

import argparse
import json
import time
from pathlib import Path

import numpy as np
from scipy.spatial.transform import Rotation

from devices.recorded import read_recorded
from planner import Pose
from planner.config import PlannerConfig
from workbench.evaluation import ORACLE, bench_recorded, recorded_truth, run_recorded, view_cover

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
    parser.add_argument("--perturb-seeds", type=int, default=10)
    parser.add_argument(
        "--registration-only", action="store_true", help="skip the planners, run the registration check"
    )
    parser.add_argument("--out", type=Path, default=None, help="write the rows as JSON here")
    args = parser.parse_args()
    t0 = time.perf_counter()
    recorded = read_recorded(args.data)
    truth = recorded_truth(recorded)
    config = PlannerConfig()
    views = len(recorded.views)
    print(f"{recorded.name}: {views} views, read in {time.perf_counter() - t0:.1f} s")
    if args.registration_only:
        registration(args, recorded, config, truth, views)
        return
    cover = view_cover(recorded, truth)
    print(
        "per view coverage of the truth (its own points, 5 mm):",
        ", ".join(f"{v.name} {c:.3f}" for v, c in zip(recorded.views, cover.mean(axis=1), strict=True)),
    )
    planners = [ORACLE, *args.planners.split(","), "random"]
    bench = bench_recorded(
        recorded,
        planners,
        config,
        seeds=args.random_seeds,
        surface=not args.no_surface,
        on_run=lambda r: print(f"  {r['planner']} seed {r['seed']}: {' '.join(r['order'])}", flush=True),
    )
    print(
        f"recorded ceiling (all views through the pipeline): coverage {bench.ceiling:.4f}, F@5mm "
        f"{bench.ceiling_fscore:.4f}, surface F@5mm {bench.ceiling_surface_fscore}"
    )
    print(f"fewest views to 95 % of the union's coverage, brute force over subsets: {bench.fewest}")
    print(bench.table())
    rows, runs, ceiling = bench.summary(), bench.rows, bench.ceiling
    registration(args, recorded, config, truth, views)
    if args.out is not None:
        args.out.write_text(json.dumps({"summary": rows, "runs": runs, "ceiling": ceiling}, indent=1))


def registration(args: argparse.Namespace, recorded, config: PlannerConfig, truth, views: int) -> None:
    """The recorded order with every pose but the first perturbed by 3 mm / 1 degree, against the unperturbed run."""
    # registration: perturbed recorded poses, with and without the scanner's edge cells
    print("\nregistration, recorded order, every pose but the first perturbed by 3 mm / 1 degree:")
    for trim in (0, 2):
        data = recorded if trim == 0 else read_recorded(args.data, edge_trim=trim)
        clean = run_recorded(data, "unperturbed", config, truth, order=list(range(views)), surface=False)
        to_clean, to_recorded, rejected = [], [], 0
        for s in range(args.perturb_seeds):
            run = run_recorded(
                data,
                "perturbed",
                config,
                truth,
                order=list(range(views)),
                surface=False,
                perturb=perturbation(s, 3.0, 1.0),
            )
            rejected += run.rejected
            for i, view in enumerate(data.views[1:], start=1):  # the first view is given exactly
                p = view.points_sensor
                to_clean.append(np.sqrt(np.mean(np.sum((run.poses[i].apply(p) - clean.poses[i].apply(p)) ** 2, 1))))
        for i, view in enumerate(data.views):
            p = view.points_sensor
            to_recorded.append(np.sqrt(np.mean(np.sum((clean.poses[i].apply(p) - view.points_world) ** 2, 1))))
        report(f"edge_trim {trim}", to_clean, to_recorded, rejected, clean.fscore[-1], args.perturb_seeds, views)
    for trim in (1, 2):
        icp_only(args, recorded, config, truth, views, trim)


def report(label: str, to_clean, to_recorded, rejected: int, fscore: float, seeds: int, views: int) -> None:
    a, b = 1000 * np.array(to_clean), 1000 * np.array(to_recorded)
    print(
        f"  {label}: unperturbed ICP moves the views off their recorded poses by median {np.median(b):.2f}"
        f" mm (max {b.max():.2f}); perturbed ({seeds} seeds x {views - 1} views) to the unperturbed"
        f" result: median {np.median(a):.2f} mm, RMS {np.sqrt(np.mean(a**2)):.2f} mm, within 1 mm"
        f" {np.mean(a <= 1.0):.0%}, max {a.max():.2f} mm; ICP rejections {rejected}; final F@5mm unperturbed"
        f" {fscore:.4f}"
    )


def icp_only(args: argparse.Namespace, recorded, config: PlannerConfig, truth, views: int, trim: int) -> None:
    """The scanner's ``trim`` outermost cells left out of registration only: ICP registers the trimmed views to the
    trimmed cloud, and the cloud scored is the untrimmed views placed by the same correction (each view's world
    error and ICP correction carried over to the untrimmed view's own sensor frame)."""
    from dataclasses import replace

    from planner import Planner
    from workbench.evaluation import accuracy

    trimmed = read_recorded(args.data, edge_trim=trim)
    no_icp = replace(config, registration=replace(config.registration, enabled=False))

    def run(perturb) -> tuple[list[Pose], float, int]:
        icp, cloud = Planner(config), Planner(no_icp)
        poses, rejected = [], 0
        for i in range(views):
            pose = trimmed.views[i].T_world_sensor
            given = pose if perturb is None else perturb(i, pose)
            done = icp.integrate(trimmed.frame(i, given))
            rejected += done.registration is not None and not done.registration.accepted
            full_given = given @ pose.inverse() @ recorded.views[i].T_world_sensor
            registered = done.T_world_camera @ given.inverse() @ full_given
            cloud.integrate(recorded.frame(i, registered))
            poses.append(registered)
        return poses, accuracy(truth, cloud.cloud).fscore_5mm, rejected

    clean, fscore, _ = run(None)
    to_clean, rejected = [], 0
    for s in range(args.perturb_seeds):
        poses, _, r = run(perturbation(s, 3.0, 1.0))
        rejected += r
        for i in range(1, views):
            p = recorded.views[i].points_sensor
            to_clean.append(np.sqrt(np.mean(np.sum((poses[i].apply(p) - clean[i].apply(p)) ** 2, 1))))
    to_recorded = [
        np.sqrt(np.mean(np.sum((clean[i].apply(v.points_sensor) - v.points_world) ** 2, 1)))
        for i, v in enumerate(recorded.views)
    ]
    report(f"edge_trim {trim} for ICP only", to_clean, to_recorded, rejected, fscore, args.perturb_seeds, views)


if __name__ == "__main__":
    main()
