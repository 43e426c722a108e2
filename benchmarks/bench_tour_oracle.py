"""How far below `projection`'s robot motion a planner that *knew the object* could get (the bound in docs/experiments/tour.md).

For each mesh and placement: `projection`'s scan in the UR5 cell (``--sensor``, 10 views), its moves to 95 % of the
ceiling; then an oracle that knows the true mesh: every candidate view about the object's *true* box rendered and
preprocessed like the planner (the samples each covers within 5 mm, as the scan's coverage counts them), every
view's free arm targets at every plate angle (the reachability cache), and a beam search over sequences of views
from the scan's first view that minimises the predicted seconds of moves (plate turn, then the slowest joint's
trapezoid, `ArmReach.seconds_between`; ``--overhead`` seconds more per view) to 95 % of the ceiling. The oracle's
best sequence is then *executed* in a fresh simulated cell (real moves, planned by the cell; real captures,
integrated by the planner; with ``--sensor`` / ``--calibration`` that sensor and calibration error; the oracle then
knows the view masks as that sensor renders them, with another noise draw, and no calibration error), so its moves
to 95 % are measured as the scans' are; after its sequence the scan goes on with `projection`'s plans to 10 views
(the AUC over views is that of these 10).

    .venv/bin/python benchmarks/bench_tour_oracle.py ../shared/models/bunny.obj --yaws 0,90 --overhead 0.3

Prints one line per (mesh, placement) and the means with the paired difference oracle - projection. It bounds what
a planner could save, not what one does: the oracle knows the surface no planner has seen (docs/experiments/tour.md).
"""

from __future__ import annotations

import argparse
import json
import math
import statistics
import time
from collections.abc import Callable
from dataclasses import dataclass, replace
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import NDArray

TARGET = 0.95
MARGIN = 0.01
"""The oracle aims this much (of the ceiling) above 95 %: its renders count a little more than a scan's cloud. When
no sequence of at most ``--max-views`` views gets there it aims at 95 %, then a point lower at a time (down to 80 %):
the executed scan, which goes on with `projection`'s plans, may still get to 95 %, else it pays the penalty."""

POPCOUNT = np.array([bin(i).count("1") for i in range(256)], dtype=np.int32)
"""Set bits of every byte (numpy >= 1.26 has no ``bitwise_count``)."""


@dataclass
class Oracle:
    """The quickest sequence a search found."""

    views: list[int]
    """Candidate indices in order (after the first view)."""
    predicted_seconds: float
    """Its moves' estimated seconds plus the per-view overhead."""
    predicted_coverage: float
    """Samples covered in the masks after it (the first view's included)."""


def _masks(
    render: Callable[[Any], NDArray[np.float32]],
    intrinsics: Any,
    samples: NDArray[np.float64],
    poses: list[Any],
    bbox: Any,
    preprocess_config: Any,
) -> NDArray[np.bool_]:
    """(V, M) bool: the samples each view covers (``workbench.evaluation.view_coverage`` of its rendered depth)."""
    from workbench.evaluation import view_coverage

    return np.array(
        [view_coverage(render(pose), pose, intrinsics, samples, bbox, preprocess_config) for pose in poses],
        dtype=bool,
    ).reshape(len(poses), len(samples))


def beam_search(
    masks: NDArray[np.bool_],
    owner: NDArray[np.int64],
    times: NDArray[np.float64],
    start_times: NDArray[np.float64],
    covered0: NDArray[np.bool_],
    goal: int,
    beam: int,
    rate: float,
    max_views: int = 9,
    overhead: float = 0.0,
) -> Oracle | None:
    """The fastest sequence of targets found to ``goal`` covered samples.

    masks (V, M) per view; owner (T,) the view of each arm target; times (T, T) move seconds between targets;
    start_times (T,) from the state after the first view. States ranked by time + samples missing / rate.
    """
    packed = np.packbits(masks, axis=1)
    lut = POPCOUNT
    states: list[tuple[float, NDArray[np.uint8], int, list[int]]] = [(0.0, np.packbits(covered0), -1, [])]
    best: Oracle | None = None
    for _ in range(max_views):
        children: list[tuple[float, float, int, int, int]] = []  # (key, t, parent, target, count)
        for p, (t, cov, last, _) in enumerate(states):
            gain = lut[packed & ~cov[None, :]].sum(axis=1)  # (V,)
            have = int(lut[cov].sum())
            row = start_times if last < 0 else times[last]
            t_new = t + row + overhead  # (T,)
            # per view, its nearest target from here
            order = np.lexsort((t_new, owner))
            first_of = np.r_[True, owner[order][1:] != owner[order][:-1]]
            nearest = order[first_of]  # one target per view, the quickest
            for j in nearest:
                v = int(owner[j])
                if not math.isfinite(t_new[j]) or gain[v] == 0:
                    continue
                count = have + int(gain[v])
                missing = max(0, goal - count)
                children.append((float(t_new[j]) + missing / rate, float(t_new[j]), p, int(j), count))
        if not children:
            break
        children.sort()
        new_states = []
        seen: set[tuple[int, ...]] = set()
        for _, t, p, j, count in children:
            path = [*states[p][3], j]
            sig = (*sorted(int(owner[x]) for x in path), j)
            if sig in seen:
                continue
            seen.add(sig)
            if count >= goal:
                if best is None or t < best.predicted_seconds:
                    best = Oracle([int(owner[x]) for x in path], t, float(count))
                continue
            if best is not None and t >= best.predicted_seconds:
                continue
            cov = states[p][1] | packed[owner[j]]
            new_states.append((t, cov, j, path))
            if len(new_states) >= beam:
                break
        states = new_states
        if not states:
            break
    return best


def run_one(model: Path, yaw: float, args: argparse.Namespace, rates: list[float], verbose: bool) -> dict[str, Any]:
    """One (mesh, placement): projection's scan, the oracle's search, the oracle's sequence executed."""
    from devices.builtins import resolve_model
    from devices.config import CameraConfig, CellConfig
    from devices.mesh import turned_about_plate_axis
    from devices.planner_noise import planner_config_for
    from devices.sim import make_sim_cell
    from planner import Planner, PlannerConfig
    from planner.candidates import propose_candidates
    from planner.types import BoundingBox
    from workbench.evaluation import (
        area_under_curve,
        coverage,
        ratio_curve,
        run_scan,
        simulate,
        time_to_reach,
        views_to_reach,
    )

    name, mesh = resolve_model(str(model), up="y", size=0.2)
    if yaw % 360:
        mesh = turned_about_plate_axis(mesh, yaw)
    sensor = {"sensor": args.sensor, "calibration": args.calibration}
    camera = CameraConfig(**sensor)
    config = planner_config_for(PlannerConfig(), camera)
    ref = simulate(name, PlannerConfig(), mesh=mesh, planner_name="projection", seed=0, **sensor)
    ceiling = float(ref.reachable_coverage or 1.0)
    samples = ref.surface_samples

    ref_cov = [float(r.coverage or 0.0) for r in ref.result.records]
    ref_moves = [r.move_seconds for r in ref.result.records]
    ref_ratios = [c / ceiling for c in ref_cov]
    ref_t, ref_views = time_to_reach(ref_ratios, ref_moves, TARGET), views_to_reach(ref_ratios, TARGET)

    # the oracle's world: candidates about the true box, masks, arm targets
    t0 = time.perf_counter()
    # the oracle's cell: the scans' sensor, no calibration error (it knows where its camera is)
    cell = make_sim_cell(mesh, CameraConfig(sensor=args.sensor), CellConfig(kinematics="urdf"), seed=1)
    vertices = np.asarray(mesh.vertices, dtype=np.float64)
    bbox = BoundingBox(vertices.min(axis=0), vertices.max(axis=0))  # the object's true box
    cell.set_object_box(bbox)
    first = cell.initial_pose()
    motion0 = cell.move_to(first)
    ideal = PlannerConfig()
    cand, _, _ = propose_candidates(bbox, ideal.candidates, ideal.partitions)
    poses = [c.T_world_camera for c in cand]
    assert cell.kinematics is not None
    reach = cell.kinematics.reach
    q0 = np.asarray(cell.arm.joint_positions(), dtype=np.float64)
    a0 = cell.turntable.angle
    owner_l, q_l, a_l = [], [], []
    for i, T in enumerate(poses):
        for q, a in reach.free_targets(T, q0, a0):
            owner_l.append(i)
            q_l.append(q)
            a_l.append(a)
    owner = np.array(owner_l, dtype=np.int64)
    qs, angles = np.stack(q_l), np.array(a_l)
    times = reach.seconds_between(qs, angles, qs, angles)
    start = reach.seconds_between(q0[None, :], np.array([a0]), qs, angles)[0]
    camera_sim: Any = cell.camera  # a SimulatedCamera (render, render_sensor)
    if args.sensor == "ideal":  # as the ceiling's render reference: one clean frame, no outlier filter
        render, clean = camera_sim.render, replace(config.preprocess, outlier_min_neighbors=0)
    else:  # the sensor's own depth (noise, dropouts, flying pixels: another draw than the scan's), its filters
        render, clean = camera_sim.render_sensor, config.preprocess
    masks = _masks(render, cell.camera.intrinsics, samples, poses, bbox, clean)
    first_mask = _masks(render, cell.camera.intrinsics, samples, [first], bbox, clean)[0]
    setup = time.perf_counter() - t0
    t1 = time.perf_counter()
    found: list[Oracle] = []
    reachable = int((masks.any(axis=0) | first_mask).sum())  # what the oracle's views can cover at all
    fractions = [TARGET + MARGIN, TARGET, *(TARGET - 0.01 * k for k in range(1, 16))]
    goals = [min(math.ceil(f * ceiling * len(samples)), reachable) for f in fractions]  # lower when out of reach
    for goal in goals:
        for rate in rates:
            o = beam_search(
                masks, owner, times, start, first_mask, goal, args.beam, rate * len(samples), args.max_views,
                args.overhead,
            )  # fmt: skip
            if o is not None:
                found.append(o)
        if found:
            break
    search = time.perf_counter() - t1
    if not found:
        return {"model": name, "yaw": yaw, "error": f"no sequence of {args.max_views} views reaches {goal} samples"}
    aimed = goal / (ceiling * len(samples))
    best = min(found, key=lambda o: o.predicted_seconds)
    if verbose:
        print(f"  oracle views {best.views}, predicted {best.predicted_seconds:.2f} s", flush=True)
        print(
            f"  projection moves {[round(m, 2) for m in ref_moves]} cov / ceiling {[round(c / ceiling, 3) for c in ref_cov]}"
        )

    # execute it: real moves and captures in a fresh cell, the planner's own cloud for coverage
    run_cell = make_sim_cell(mesh, camera, CellConfig(kinematics="urdf"), seed=0)
    run_cell.set_object_box(bbox)
    planner = Planner(replace(config, termination=replace(config.termination, max_views=11)))  # see below
    run_cell.move_to(first)
    planner.integrate(run_cell.capture())
    exec_cov, exec_moves = [coverage(samples, planner.cloud)], [0.0]
    for v in best.views:
        motion = run_cell.move_to(poses[v])
        planner.integrate(run_cell.capture())
        exec_cov.append(coverage(samples, planner.cloud))
        exec_moves.append(float(motion.duration or 0.0))
        if verbose:
            print(
                f"  view {v}: move {exec_moves[-1]:.2f} s, plate {math.degrees(motion.angle):.0f} deg, "
                f"cov / ceiling {exec_cov[-1] / ceiling:.3f}"
            )
    # short of 10 views, the scan goes on with projection's plans (run_scan from the last view, which it takes
    # again: a frame the planner already has, so the planner may integrate 11)
    if len(exec_cov) < 10:
        rest = run_scan(planner, run_cell, samples, first_pose=poses[best.views[-1]])
        exec_cov += [float(r.coverage or 0.0) for r in rest.records[1:]]
        exec_moves += [r.move_seconds for r in rest.records[1:]]
    ex_ratios = [c / ceiling for c in exec_cov]
    ex_t, ex_views = time_to_reach(ex_ratios, exec_moves, TARGET), views_to_reach(ex_ratios, TARGET)
    ref_auc = area_under_curve(ratio_curve(ref_cov, ceiling, 10))
    ex_auc = area_under_curve(ratio_curve(exec_cov, ceiling, 10))
    return {
        "model": name,
        "yaw": yaw,
        "ceiling": ceiling,
        "projection_moves": ref_t,
        "projection_views": ref_views,
        "oracle_predicted": best.predicted_seconds,
        "oracle_aimed": aimed,
        "oracle_views": len(best.views) + 1,
        "oracle_moves": ex_t,
        "oracle_exec_views": ex_views,
        "first_move": float(motion0.duration or 0.0),
        "projection_auc": ref_auc,
        "oracle_auc": ex_auc,
        "projection_final": ref_cov[-1] / ceiling,
        "oracle_final": exec_cov[-1] / ceiling,
        "targets": len(owner),
        "setup_s": setup,
        "search_s": search,
    }


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("models", nargs="+", type=Path)
    parser.add_argument("--yaws", default="0,90")
    parser.add_argument("--beam", type=int, default=64)
    parser.add_argument("--max-views", type=int, default=9, help="views after the first (a scan of 10 views: 9)")
    parser.add_argument("--overhead", type=float, default=0.0, help="seconds each view costs in the search")
    parser.add_argument("--sensor", default="ideal", help="the scans' sensor (also the oracle's renders)")
    parser.add_argument("--calibration", default="none")
    parser.add_argument("--json", type=Path, default=None, help="write the rows here")
    parser.add_argument("--verbose", action="store_true", help="each sequence and its moves")
    parser.add_argument("--rates", default="0.02,0.05,0.1", help="coverage per second assumed for what is missing")
    args = parser.parse_args()
    from workbench.evaluation import paired_comparison

    rates = [float(r) for r in args.rates.split(",")]
    rows = []
    for model in args.models:
        for yaw in (float(y) for y in args.yaws.split(",")):
            row = run_one(model, yaw, args, rates, args.verbose)
            rows.append(row)
            if "error" in row:
                print(f"{row['model']:>14} yaw {yaw:>4.0f}: {row['error']}", flush=True)
                continue
            print(
                f"{row['model']:>14} yaw {yaw:>4.0f}: projection {row['projection_moves']:6.2f} s "
                f"({row['projection_views']} views) | oracle predicted {row['oracle_predicted']:6.2f} s, "
                f"executed {row['oracle_moves']:6.2f} s ({row['oracle_exec_views']} views) | "
                f"AUC {100 * row['projection_auc']:.1f} / {100 * row['oracle_auc']:.1f}",
                flush=True,
            )
    if args.json is not None:
        args.json.write_text(json.dumps(rows, indent=1))
    ok = {(r["model"], r["yaw"]): r for r in rows if "error" not in r}
    paired = paired_comparison(
        {k: r["oracle_moves"] for k, r in ok.items()},
        {k: r["projection_moves"] for k, r in ok.items()},
        higher_is_better=False,
    )
    if paired is not None and paired.low is not None and paired.high is not None:
        mp = statistics.fmean(r["projection_moves"] for r in ok.values())
        mo = statistics.fmean(r["oracle_moves"] for r in ok.values())
        print(
            f"\n{paired.n} pairs: projection {mp:.2f} s, oracle executed {mo:.2f} s ({100 * (mo / mp - 1):+.1f} %), "
            f"paired {paired.mean:+.2f} [{paired.low:+.2f}, {paired.high:+.2f}] (95 % t-interval), wins "
            f"{paired.wins} / ties {paired.ties} / losses {paired.losses}; AUC "
            f"{100 * statistics.fmean(r['projection_auc'] for r in ok.values()):.2f} / "
            f"{100 * statistics.fmean(r['oracle_auc'] for r in ok.values()):.2f}"
        )


if __name__ == "__main__":
    main()
