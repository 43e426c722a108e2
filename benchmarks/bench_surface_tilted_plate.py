"""The surface when a registration tilts the plate: F@5mm of the surface and of the cloud, and the frames whose plate
the integrator finds tilted (``workbench.surface.frame_plate_plane``).

Run: ``PYTHONPATH=$PWD OMP_NUM_THREADS=1 .venv/bin/python benchmarks/bench_surface_tilted_plate.py MESH [MESH ...]
[--planner path] [--move-capture-hz 2.5] [--sensor ideal]``

Per mesh: a headless scan (``workbench.evaluation.simulate``: the UR5 cell, ``--planner``, capture during moves at
``--move-capture-hz``) feeds every view and kept move frame, at its registered pose, to a
:class:`workbench.surface.SurfaceIntegrator`. Printed: the final surface's F@5mm and precision@5mm, the cloud's
F@5mm, the surface's F@5mm after each of the first views, and for each frame whose plate was found tilted its tilt
(degrees). ICP may turn a low view of a near-symmetric object (the screwdriver) by 5-7 degrees about its axis:
the object still fits, the plate seen through that pose does not lie at z = 0 (docs/experiments/surface.md).
"""

from __future__ import annotations

import argparse
import dataclasses
import math
import os
from typing import Any

import numpy as np

from devices.config import CameraConfig, CellConfig
from planner import DepthFrame, PlannerConfig
from workbench.evaluation import simulate
from workbench.surface import (
    SurfaceIntegrator,
    cloud_accuracy,
    frame_plate_plane,
    ground_truth,
    surface_accuracy,
    surface_config_for,
)


def run(model: str, planner: str, hz: float, sensor: str, first_views: int) -> dict[str, Any]:
    """The scan of ``model`` and its surface's scores (see the module docstring)."""
    tilts: list[float] = []
    surface = SurfaceIntegrator(surface_config_for(CameraConfig(sensor=sensor)))
    frames: list[tuple[str, DepthFrame]] = []

    def fuse(kind: str, frame: DepthFrame) -> None:
        frames.append((kind, frame))
        box = surface.box  # the plate is fitted against the object's box before this frame, as the integrator does
        plane = np.zeros(3) if box is None else frame_plate_plane(frame.points_world, surface.config, box)
        if plane.any():
            tilts.append(math.degrees(math.atan(math.hypot(plane[0], plane[1]))))
        surface.integrate(frame)

    cell = dataclasses.replace(CellConfig(), move_capture_hz=hz)
    scan = simulate(
        model,
        PlannerConfig(),
        planner_name=planner,
        cell=cell,
        reachable=False,
        on_frame=lambda frame: fuse("view", frame),
        on_move_frame=lambda frame: fuse("move", frame),
        sensor=sensor,
    )
    truth = ground_truth(scan.mesh, scan.surface_samples)
    final = surface_accuracy(surface.mesh(), truth)
    early: list[str] = []
    replay = SurfaceIntegrator(surface.config)
    for kind, frame in frames[:first_views]:
        replay.integrate(frame)
        early.append(f"{kind} {surface_accuracy(replay.mesh(), truth).fscore_5mm:.3f}")
    cloud = cloud_accuracy(scan.planner.cloud, truth).fscore_5mm
    return {
        "surface_f5": final.fscore_5mm,
        "surface_precision5": final.precision_5mm,
        "cloud_f5": cloud,
        "early": early,
        "tilted_frames": len(tilts),
        "tilts_deg": [round(t, 2) for t in tilts],
        "frames": len(frames),
    }


def main() -> None:
    parser = argparse.ArgumentParser(description=(__doc__ or "").split("\n\n")[0])
    parser.add_argument("models", nargs="+")
    parser.add_argument("--planner", default="path")
    parser.add_argument("--move-capture-hz", type=float, default=2.5)
    parser.add_argument("--sensor", default="ideal")
    parser.add_argument("--first-views", type=int, default=4, help="score the surface after each of these frames")
    args = parser.parse_args()
    print(f"load average {os.getloadavg()}")
    for model in args.models:
        r = run(model, args.planner, args.move_capture_hz, args.sensor, args.first_views)
        print(
            f"{model}: surface F@5mm {r['surface_f5']:.3f} precision@5mm {r['surface_precision5']:.3f}, "
            f"cloud F@5mm {r['cloud_f5']:.3f}; {r['frames']} frames; first: {', '.join(r['early'])}; "
            f"plate found tilted in {r['tilted_frames']}: {r['tilts_deg']} deg"
        )


if __name__ == "__main__":
    main()
