"""Does calibrating help a scan? F@5mm of a headless scan at 'none', at 'poor', and at 'poor' after calibration.

Run: ``.venv/bin/python benchmarks/bench_calibration_scan.py [--model ../shared/models/bunny.obj] [--seeds 0,1,2]``.

Per seed: the calibration routine runs on the simulated cell (the sphere target on the plate); then three scans of
the model, same seed, same sensor: with no calibration error ('none'), with the drawn 'poor' errors and the nominal
values, and with the same physical cell after applying the recovered hand-eye transform and axis offset (the arm
model's ``T_flange_camera`` set to the estimate, its base moved by the axis offset, so the true camera is the same
one: the drawn error re-expressed against the new nominal values, ``E' = X_est^-1 @ X_true``). Goal: the
calibrated scan's F@5mm within 1 point of the 'none' scan's.
"""

from __future__ import annotations

import argparse
import dataclasses
import functools
import statistics
import time
from typing import Any

import numpy as np

from devices.builtins import resolve_model
from devices.calibration import calibrate_sim
from devices.config import CameraConfig, CellConfig
from devices.mesh import sample_surface
from devices.planner_noise import planner_config_for
from devices.sim import make_sim_cell
from planner import Planner
from planner.config import PlannerConfig
from planner.types import Pose
from workbench.evaluation import GroundTruth, run_scan


def _scan(mesh: Any, camera: CameraConfig, cell_config: CellConfig, seed: int, patch: Any = None) -> float:
    cell = make_sim_cell(mesh, camera, cell_config, seed=seed)
    if patch is not None:
        patch(cell)
    samples = sample_surface(mesh, 10_000, seed=seed)
    planner = Planner(planner_config_for(PlannerConfig(), camera))
    result = run_scan(planner, cell, samples, truth=GroundTruth.of(mesh, samples))
    accuracy = result.records[-1].accuracy
    assert accuracy is not None
    return 100.0 * float(accuracy["fscore_5mm"])


def _same_physical_cell(cell: Any, X_est: Pose, X_true: Pose, centre: np.ndarray) -> None:
    """The drawn errors re-expressed against the calibrated nominal values (the true camera and axis unchanged)."""
    cell.errors.E_hand_eye = X_est.inverse() @ X_true
    cell.errors.T_base_axis = Pose(np.eye(3), -centre) @ cell.errors.T_base_axis


def main() -> None:
    parser = argparse.ArgumentParser(description=(__doc__ or "").splitlines()[0])
    parser.add_argument("--model", default="/work/shared/models/bunny.obj")
    parser.add_argument("--seeds", default="0,1,2")
    parser.add_argument("--sensor", default="realsense-d435")
    args = parser.parse_args()
    _, mesh = resolve_model(args.model, up="y", size=0.2)
    print(f"model={args.model} sensor={args.sensor}")
    print("seed  F@5mm none   poor  calibrated | calibrated - none | seconds")
    gaps = []
    for seed in (int(s) for s in args.seeds.split(",")):
        t0 = time.perf_counter()
        cal = calibrate_sim(args.sensor, "poor", seed)
        rec = cal["recovered"]
        X_est = Pose.from_matrix(rec["T_flange_camera"])
        X_true = Pose.from_matrix(cal["true"]["T_flange_camera"])
        centre = np.array([rec["axis_point"][0], rec["axis_point"][1], 0.0])
        none = _scan(mesh, CameraConfig(sensor=args.sensor), CellConfig(), seed)
        poor_camera = CameraConfig(sensor=args.sensor, calibration="poor")
        poor = _scan(mesh, poor_camera, CellConfig(), seed)
        base = CellConfig()
        arm = dataclasses.replace(
            base.arm,
            T_flange_camera=tuple(tuple(float(v) for v in row) for row in X_est.matrix),
            base=tuple(float(v) for v in np.asarray(base.arm.mount) - centre),
        )

        corrected = functools.partial(_same_physical_cell, X_est=X_est, X_true=X_true, centre=centre)
        calibrated = _scan(mesh, poor_camera, dataclasses.replace(base, arm=arm), seed, corrected)
        gaps.append(calibrated - none)
        print(
            f"{seed:4d} {none:10.2f} {poor:6.2f} {calibrated:11.2f} | {calibrated - none:+17.2f} |"
            f" {time.perf_counter() - t0:7.1f}",
            flush=True,
        )
    print(f"median gap {statistics.median(gaps):+.2f} points, worst {min(gaps):+.2f}")


if __name__ == "__main__":
    main()
