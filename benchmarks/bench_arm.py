"""What the arm costs: IK + collision checks per plan, trajectory planning per view, and its share of plan_seconds.

Run: ``PYTHONPATH=. .venv/bin/python benchmarks/bench_arm.py [--model ../shared/models/bunny.obj] [--views 10]``.

One scan of the model with the UR5 (the default cell) and one with the reach-sphere cell, same seed. Prints:

1. IK + collision checks of the 400 candidates of each plan (the cell's ``is_reachable`` over the hemisphere,
   caches as in a session): median and max seconds per plan (goal: median <= 0.1 s on 2 cores);
2. trajectory planning per approved view (``plan_motion``: plate angle + IK branches + path + timing): median and
   max seconds (goal: median <= 0.3 s);
3. median ``plan_seconds`` with the arm and with the reach sphere, and the difference (the reachability test
   runs inside the planner's "select" stage);

(1 and 2 also as the thread's CPU time: on a loaded machine the wall time includes waiting for a core,)

4. every ``plan_path`` of the scan (the approved moves, the retracts, and the refused ones), by method:
   how many were a straight line and how many needed RRT-Connect, with their wall time;
5. moves that need RRT-Connect (two moves of the UR5 around a box of 5, 8 and 12 cm on the straight line, three
   seeds, each query twice): ``plan_path`` wall and CPU time, the move durations, and whether each repeat gave
   the same waypoints (it must: the planner is deterministic);

6. the same UR5 scan with the reachability cache (per view, plate angle and object box) and the swept-box turn
   test off: its median plan_seconds and reachability per plan, and whether both scans made the same plans
   (every plan's chosen view and eligible set);

and the share of the first hemisphere the arm reaches, with the reasons for the rest.
``--sensor realsense-d435 --calibration typical`` scans with a realistic sensor. ``--repeat N`` makes N scans with
each cell, alternating, and prints each scan's median plan and their median (and the arm's plan CPU seconds): the
two shared cores' speed changes by up to 2x within minutes, so one scan's median is no verdict. Scans after the
first find its IK anchors (kept per process, as a server's sessions of one object find them); sections 1, 2, 4 and 6
are of the first scan.
"""

from __future__ import annotations

import argparse
import collections
import statistics
import time
from pathlib import Path
from typing import Any

import numpy as np

import devices.arm.kinematics as arm_kinematics
from devices.arm.config import ArmConfig
from devices.arm.motion import NoPathError, plan_path, time_path
from devices.builtins import resolve_model
from devices.config import CameraConfig, CellConfig
from devices.planner_noise import planner_config_for
from devices.sim import make_sim_cell
from planner import Planner, PlannerConfig, PlanResult
from workbench.evaluation import IterationRecord, run_scan


def timed_scan(
    model: str, views: int, kinematics: str, seed: int, cache: bool = True, camera: CameraConfig | None = None
) -> dict[str, Any]:
    """Scan with the given arm, timing the cell's reachability per plan and its motion planning per move.
    cache: the UR5's reachability cache and swept-box turn test on (off: every attempt computed afresh)."""
    name, mesh = resolve_model(model, up="y", size=0.2)
    camera = camera or CameraConfig()
    t0 = time.perf_counter()
    cell = make_sim_cell(mesh, camera, CellConfig(kinematics=kinematics), seed=seed)  # type: ignore[arg-type]
    build = time.perf_counter() - t0
    if cell.kinematics is not None:
        cell.kinematics.reach.use_attempt_cache = cache
        cell.kinematics.use_sweep_test = cache
    reach_seconds = [0.0]
    reach_cpu = [0.0]
    motion_seconds: list[float] = []
    motion_cpu: list[float] = []
    is_reachable, plan_motion = cell.is_reachable, cell.plan_motion

    def timed_reachable(pose: Any) -> bool:
        t, c = time.perf_counter(), time.thread_time()
        try:
            return is_reachable(pose)
        finally:
            reach_seconds[-1] += time.perf_counter() - t
            reach_cpu[-1] += time.thread_time() - c

    def timed_motion(*args: Any, **kwargs: Any) -> Any:
        t, c = time.perf_counter(), time.thread_time()
        try:
            return plan_motion(*args, **kwargs)
        finally:
            motion_seconds.append(time.perf_counter() - t)
            motion_cpu.append(time.thread_time() - c)

    paths: dict[str, list[float]] = collections.defaultdict(list)
    plan_path = arm_kinematics.plan_path

    def timed_path(*args: Any, **kwargs: Any) -> Any:
        t = time.perf_counter()
        try:
            path = plan_path(*args, **kwargs)
        except arm_kinematics.NoPathError:
            paths["no_path"].append(time.perf_counter() - t)
            raise
        paths[path.method].append(time.perf_counter() - t)
        return path

    arm_kinematics.plan_path = timed_path  # type: ignore[assignment]
    cell.is_reachable = timed_reachable  # type: ignore[method-assign]
    cell.plan_motion = timed_motion  # type: ignore[method-assign]
    per_plan: list[float] = []
    per_plan_cpu: list[float] = []
    first_plan: list[PlanResult] = []
    choices: list[tuple[int | None, tuple[bool, ...]]] = []

    def done(record: IterationRecord, plan: PlanResult) -> None:
        choices.append((plan.best_index, tuple(s.eligible for s in plan.scores)))
        per_plan.append(reach_seconds[-1])
        per_plan_cpu.append(reach_cpu[-1])
        reach_seconds.append(0.0)
        reach_cpu.append(0.0)
        if not first_plan:
            first_plan.append(plan)

    config = PlannerConfig.from_dict({"termination": {"max_views": views}, "cluster": {"seed": seed}})
    try:
        result = run_scan(Planner(planner_config_for(config, camera)), cell, on_iteration=done)
    finally:
        arm_kinematics.plan_path = plan_path  # type: ignore[assignment]
    reasons: collections.Counter[str] = collections.Counter()
    if first_plan:
        for ok, reason in cell.reachability_many([c.T_world_camera for c in first_plan[0].candidates]):
            reasons["reachable" if ok else str(reason)] += 1
    return {
        "name": name,
        "build": build,
        "reach_per_plan": per_plan,
        "reach_per_plan_cpu": per_plan_cpu,
        "motion": motion_seconds[1:],  # the first is the move to the initial view, already there
        "motion_cpu": motion_cpu[1:],
        "plan_seconds": [r.plan_seconds for r in result.records],
        "plan_cpu_seconds": [r.plan_cpu_seconds for r in result.records],
        "robot_seconds": result.robot_seconds,
        "move_seconds": sum(float((r.move or {}).get("move_duration") or 0.0) for r in result.records),
        "paths": dict(paths),
        "reasons": reasons,
        "choices": choices,
    }


def rrt_moves() -> dict[str, Any]:
    """plan_path around an obstacle on the straight line (moves that need RRT-Connect), each query twice."""
    kin = arm_kinematics.ArmKinematics(ArmConfig(), plate_radius=0.2, plate_thickness=0.02)
    q_a = np.radians([0.0, -90.0, 90.0, -90.0, -90.0, 0.0])
    out: dict[str, Any] = {"wall": [], "cpu": [], "durations": [], "differ": 0, "queries": 0, "refused": 0}
    for dq in ([1.2, 0.35, -0.5, 0.2, 0.0, 0.3], [-1.0, 0.3, -0.4, 0.0, 0.4, 0.0]):
        q_b = q_a + np.array(dq)
        middle = kin.camera_pose(0.5 * (q_a + q_b)).translation
        for size in (0.05, 0.08, 0.12):
            kin.set_object_box(middle - size, middle + size)
            if kin.world.collision(q_a, 0.0) is not None or kin.world.collision(q_b, 0.0) is not None:
                continue
            for seed in range(3):
                paths = []
                for _ in range(2):
                    t, c = time.perf_counter(), time.thread_time()
                    try:
                        paths.append(plan_path(kin.world, q_a, q_b, 0.0, seed=seed).waypoints)
                    except NoPathError:
                        out["refused"] += 1
                        paths.append(None)
                    out["wall"].append(time.perf_counter() - t)
                    out["cpu"].append(time.thread_time() - c)
                    if paths[-1] is not None:
                        out["durations"].append(time_path(kin.model, paths[-1]).duration)
                out["queries"] += 1
                same = paths[0] is not None and paths[1] is not None and np.array_equal(paths[0], paths[1])
                out["differ"] += 0 if same else 1
    return out


def stats(values: list[float]) -> str:
    if not values:
        return "-"
    return f"median {statistics.median(values):.3f} s, max {max(values):.3f} s (n = {len(values)})"


def main() -> int:
    p = argparse.ArgumentParser(description=(__doc__ or "").splitlines()[0])
    p.add_argument("--model", default=str(Path("../shared/models/bunny.obj")))
    p.add_argument("--views", type=int, default=10)
    p.add_argument("--seed", type=int, default=0)
    p.add_argument("--sensor", default="ideal", help="the depth sensor's model (e.g. realsense-d435)")
    p.add_argument("--calibration", default="none", help="the cell's calibration error (e.g. typical)")
    p.add_argument(
        "--repeat",
        type=int,
        default=1,
        help="scans with the UR5 and with the reach sphere, alternating (3: the median plan of each scan and their "
        "median: the machine's speed changes by up to 2x within minutes, so one scan is not a verdict)",
    )
    args = p.parse_args()
    if args.repeat < 1:
        p.error("--repeat: must be >= 1")
    camera = CameraConfig(sensor=args.sensor, calibration=args.calibration)
    arms, spheres = [], []
    for _ in range(args.repeat):
        arms.append(timed_scan(args.model, args.views, "urdf", args.seed, camera=camera))
        spheres.append(timed_scan(args.model, args.views, "reach_sphere", args.seed, camera=camera))
    arm, sphere = arms[0], spheres[0]
    uncached = timed_scan(args.model, args.views, "urdf", args.seed, cache=False, camera=camera)
    print(f"{arm['name']}, {args.views} views, seed {args.seed} (UR5 cell built in {arm['build']:.2f} s)")
    print(f"1. IK + collisions of the 400 candidates, per plan: {stats(arm['reach_per_plan'])}")
    print(f"   its CPU time (the wall time on an idle core): {stats(arm['reach_per_plan_cpu'])}")
    print(f"   (reach sphere, per plan: {stats(sphere['reach_per_plan'])})")
    print(f"2. trajectory planning per approved view: {stats(arm['motion'])}")
    print(f"   its CPU time: {stats(arm['motion_cpu'])}")
    arm_plan, sphere_plan = statistics.median(arm["plan_seconds"]), statistics.median(sphere["plan_seconds"])
    print(
        f"3. median plan_seconds: arm {arm_plan:.3f} s, reach sphere {sphere_plan:.3f} s, "
        f"the arm adds {arm_plan - sphere_plan:+.3f} s"
    )
    if args.repeat > 1:
        per_arm = [statistics.median(a["plan_seconds"]) for a in arms]
        per_sphere = [statistics.median(s["plan_seconds"]) for s in spheres]
        cpu_arm = [statistics.median(a["plan_cpu_seconds"]) for a in arms]
        print(
            f"   {args.repeat} scans each: arm "
            + " ".join(f"{v:.3f}" for v in per_arm)
            + f" s (median {statistics.median(per_arm):.3f} s), reach sphere "
            + " ".join(f"{v:.3f}" for v in per_sphere)
            + f" s (median {statistics.median(per_sphere):.3f} s)"
        )
        print(
            "   the arm's median plan CPU seconds: "
            + " ".join(f"{v:.3f}" for v in cpu_arm)
            + f" (median {statistics.median(cpu_arm):.3f} s); the same plans in every scan: {all(a['choices'] == arm['choices'] for a in arms)}"
        )
    total = sum(arm["reasons"].values())
    parts = ", ".join(f"{k} {v}" for k, v in arm["reasons"].most_common())
    print(f"first hemisphere: {arm['reasons']['reachable']}/{total} reachable by the UR5 ({parts})")
    print("4. plan_path per method: " + "; ".join(f"{m} {stats(v)}" for m, v in sorted(arm["paths"].items())))
    rrt = rrt_moves()
    print(f"5. moves that need RRT-Connect: plan_path {stats(rrt['wall'])}; CPU {stats(rrt['cpu'])}")
    d = rrt["durations"]
    print(
        f"   move durations {min(d):.2f}-{max(d):.2f} s (median {statistics.median(d):.2f} s); "
        f"{rrt['differ']} of {rrt['queries']} repeated queries gave other waypoints, {rrt['refused']} refused"
    )
    print(
        f"6. without the reachability cache: median plan_seconds {statistics.median(uncached['plan_seconds']):.3f} s "
        f"(with it {arm_plan:.3f} s); IK + collisions per plan {stats(uncached['reach_per_plan'])}"
    )
    same = arm["choices"] == uncached["choices"]
    print(f"   the same plans (chosen view and eligible set of all {len(arm['choices'])} plans): {same}")
    print(f"robot time of the scan: arm {arm['robot_seconds']:.1f} s, reach sphere {sphere['robot_seconds']:.1f} s")
    print(f"   the arm's move durations (no wall-clock part): {arm['move_seconds']:.6f} s")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
