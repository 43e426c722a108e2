"""Capture during moves: what the frames taken along the moves buy (robot time to 90/95 % of the ceiling, final
coverage, F@5mm of the cloud and the surface) and what they cost (render, integration seconds per move against the
move's modelled duration), at a few rates and keep rules. docs/experiments/move-capture.md reports its numbers.

Run: ``PYTHONPATH=. .venv/bin/python benchmarks/bench_move_capture.py [--model ../shared/models/bunny.obj]
[--views 10] [--rates 0,2.5,5] [--sensors ideal,realsense-d435] [--min-new 0.02] [--max-speed 0.8] [--registered]
[--repeat 1] [--cost N]``.

One simulated scan (the UR5 cell, the ``projection`` planner) per (sensor, rate); a realistic sensor scans with the
``typical`` calibration. Per scan one line: robot seconds to 90 and 95 % of the reachable-coverage ceiling (each
move frame counted at its time within its move; ``t95m`` counts the moves only, not the plans' and captures' wall
seconds, so it does not change with the machine's load), the final coverage and F@5mm (cloud, surface), the move frames
taken / kept, and per move the integration seconds against the move's duration (median and max of their ratio,
the largest modelled wait), plus the mean render seconds of one move frame. ``--repeat`` repeats each scan: the
coverage numbers repeat exactly, the seconds vary with the machine's load (``uptime`` is printed).
``--cost N``: only the wall and CPU milliseconds of one move frame (render, integrate), the median of N.
"""

from __future__ import annotations

import argparse
import dataclasses
import os
import statistics
import time
from typing import Any

from devices.config import CameraConfig, CellConfig
from devices.move_capture import SimulatedMoveCapture
from planner import PlannerConfig
from workbench.evaluation import TIME_THRESHOLDS, simulate, time_to_reach
from workbench.surface import SurfaceIntegrator, surface_block, surface_config_for


def one_scan(
    model: str,
    views: int,
    sensor: str,
    hz: float,
    min_new: float,
    wait: float,
    registered: bool = False,
    max_speed: float = CellConfig().move_capture_max_speed,
) -> dict[str, Any]:
    calibration = "none" if sensor == "ideal" else "typical"
    config = dataclasses.replace(
        PlannerConfig(), termination=dataclasses.replace(PlannerConfig().termination, max_views=views)
    )
    cell = CellConfig(
        move_capture_hz=hz,
        move_capture_min_new=min_new,
        move_capture_wait=wait,
        move_capture_registered=registered,
        move_capture_max_speed=max_speed,
    )
    surface = SurfaceIntegrator(surface_config_for(CameraConfig(sensor=sensor, calibration=calibration)))
    renders: list[float] = []
    original = SimulatedMoveCapture.render

    def timed_render(self: SimulatedMoveCapture, path: object, stamp: float) -> object:
        t0 = time.perf_counter()
        out = original(self, path, stamp)  # type: ignore[arg-type]
        renders.append(time.perf_counter() - t0)
        return out

    SimulatedMoveCapture.render = timed_render  # type: ignore[method-assign]
    try:
        scan = simulate(
            model,
            config,
            cell=cell,
            arm=None,
            sensor=sensor,
            calibration=calibration,
            on_frame=surface.integrate,
            on_move_frame=surface.integrate,
        )
    finally:
        SimulatedMoveCapture.render = original  # type: ignore[method-assign]
    records = scan.result.records
    ceiling = scan.reachable_coverage or 1.0
    ratios = [float(r.coverage or 0.0) / ceiling for r in records]
    seconds = [r.robot_seconds for r in records]
    moves = [[(f["t"], f["coverage"] / ceiling) for f in r.move_frames if f["coverage"] is not None] for r in records]
    blocks = [r.move_capture for r in records if r.move_capture is not None]
    share = [b["integration_seconds"] / b["move_seconds"] for b in blocks if b["move_seconds"] > 0]
    integrated = [b["integration_seconds"] / b["kept"] for b in blocks if b["kept"]]
    _, block = surface_block(surface, scan.mesh, scan.surface_samples)
    acc = records[-1].accuracy or {}
    return {
        "sensor": sensor,
        "hz": hz,
        **{f"t{round(100 * t)}": time_to_reach(ratios, seconds, t, moves) for t in TIME_THRESHOLDS},
        "t95m": time_to_reach(ratios, [r.move_seconds for r in records], 0.95, moves),
        "coverage": records[-1].coverage,
        "ratio": ratios[-1],
        "f5_cloud": acc.get("fscore_5mm"),
        "f5_surface": block.get("fscore_5mm"),
        "taken": sum(b["taken"] for b in blocks),
        "kept": sum(b["kept"] for b in blocks),
        "move_s": sum(b["move_seconds"] for b in blocks),
        "integ_s": sum(b["integration_seconds"] for b in blocks),
        "share_med": statistics.median(share) if share else 0.0,
        "share_max": max(share) if share else 0.0,
        "wait_max": max((b["wait_seconds"] for b in blocks), default=0.0),
        "per_kept": statistics.mean(integrated) if integrated else 0.0,
        "render": statistics.mean(renders) if renders else 0.0,
        "robot": scan.result.robot_seconds,
    }


def frame_cost(model: str, sensor: str, frames: int) -> dict[str, float]:
    """Wall and CPU milliseconds of one move frame (rendered along a move from the first view, then integrated into
    the map: preprocessing, ICP, voxel map), the median over ``frames`` frames."""
    from devices.builtins import resolve_model
    from devices.move_capture import MovePath, capture_times
    from devices.sim import make_sim_cell
    from planner import Planner
    from tests.helpers import orbit_view

    calibration = "none" if sensor == "ideal" else "typical"
    _, mesh = resolve_model(model, up="y", size=0.2)
    cell = make_sim_cell(mesh, CameraConfig(sensor=sensor, calibration=calibration), CellConfig(), seed=0)
    planner = Planner(PlannerConfig())
    planner.integrate(cell.capture())
    motion = cell.plan_motion(orbit_view([0.0, 0.0, 0.08], 30, 60, 0.45))
    path = MovePath.of(cell, motion)
    assert cell.move_capture is not None
    out: dict[str, list[float]] = {
        "render_wall": [],
        "render_cpu": [],
        "integrate_wall": [],
        "integrate_cpu": [],
        "preprocess": [],
        "register": [],
        "map": [],
    }
    for t in capture_times(path.duration, frames / path.duration)[:frames]:
        w, c = time.perf_counter(), time.process_time()
        frame = cell.move_capture.render(path, float(t))
        out["render_wall"].append(time.perf_counter() - w)
        out["render_cpu"].append(time.process_time() - c)
        w, c = time.perf_counter(), time.process_time()
        try:
            timings = planner.integrate(frame, move_frame=True).timings
        except ValueError:
            timings = {}
        out["integrate_wall"].append(time.perf_counter() - w)
        out["integrate_cpu"].append(time.process_time() - c)
        for key, stage in (("preprocess", "preprocess"), ("register", "register"), ("map", "integrate")):
            out[key].append(timings.get(stage, 0.0))
    return {k: 1000 * statistics.median(v) for k, v in out.items()}


def main() -> None:
    parser = argparse.ArgumentParser(description=(__doc__ or "").split("\n\n")[0])
    parser.add_argument("--model", default="../shared/models/bunny.obj")
    parser.add_argument("--views", type=int, default=10)
    parser.add_argument("--rates", default="0,2.5,5")
    parser.add_argument("--sensors", default="ideal,realsense-d435")
    parser.add_argument("--min-new", type=float, default=CellConfig().move_capture_min_new)
    parser.add_argument("--wait", type=float, default=CellConfig().move_capture_wait)
    parser.add_argument("--repeat", type=int, default=1)
    parser.add_argument("--registered", action="store_true", help="keep only the move frames ICP accepted")
    parser.add_argument(
        "--max-speed",
        type=float,
        default=CellConfig().move_capture_max_speed,
        help="keep only frames slower than this, m/s (0: any)",
    )
    parser.add_argument("--cost", type=int, default=0, help="only the cost of N move frames per sensor")
    args = parser.parse_args()
    if args.cost:
        print(
            f"load: {os.getloadavg()}  one move frame, median of {args.cost} (ms): render wall/CPU, integrate wall/CPU"
        )
        for sensor in args.sensors.split(","):
            c = frame_cost(args.model, sensor, args.cost)
            print(
                f"{sensor:<15} render {c['render_wall']:6.1f} / {c['render_cpu']:6.1f}   "
                f"integrate {c['integrate_wall']:6.1f} / {c['integrate_cpu']:6.1f}   (wall: preprocess "
                f"{c['preprocess']:5.1f}, ICP {c['register']:5.1f}, voxel map {c['map']:5.1f})"
            )
        print(f"load: {os.getloadavg()}")
        return
    print(
        f"load: {os.getloadavg()}  model {args.model}, {args.views} views, min_new {args.min_new}, wait {args.wait}, "
        f"registered {args.registered}, max speed {args.max_speed}"
    )
    head = "sensor          Hz    t90    t95   t95m  cover  ratio  F5cld  F5srf  taken kept  move_s integ_s med%  max%  wait  ms/kept ms/render"
    print(head)
    for _ in range(args.repeat):
        for sensor in args.sensors.split(","):
            for hz in (float(v) for v in args.rates.split(",")):
                r = one_scan(
                    args.model, args.views, sensor, hz, args.min_new, args.wait, args.registered, args.max_speed
                )
                print(
                    f"{r['sensor']:<15} {r['hz']:>3.1f} {r['t90']:>6.1f} {r['t95']:>6.1f} {r['t95m']:>6.1f} "
                    f"{r['coverage']:.4f} "
                    f"{r['ratio']:.4f} {r['f5_cloud']:.4f} {r['f5_surface']:.4f} {r['taken']:>5} {r['kept']:>4} "
                    f"{r['move_s']:>7.1f} {r['integ_s']:>7.2f} {100 * r['share_med']:>4.0f} {100 * r['share_max']:>5.0f} "
                    f"{r['wait_max']:>5.2f} {1000 * r['per_kept']:>7.0f} {1000 * r['render']:>9.1f}",
                    flush=True,
                )
    print(f"load: {os.getloadavg()}")


if __name__ == "__main__":
    main()
