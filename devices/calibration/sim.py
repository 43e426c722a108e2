"""Calibration in simulation: a simulated cell with the target on its plate, and the truth to check against."""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

import numpy as np
from numpy.typing import NDArray

from devices.calibration.poses import PLATE_ANGLES_DEG, CalibrationPose
from devices.calibration.result import CalibrationResult, Capture, axis_error, pose_error
from devices.calibration.target import DEFAULT_TARGET, SphereTarget
from devices.cell import Cell
from devices.config import CameraConfig, CellConfig
from planner.types import Pose


@dataclass(frozen=True, eq=False)
class SimTruth:
    """The simulated cell's true hand-eye transform and turntable axis (point on z = 0 and direction, base frame)."""

    T_flange_camera: Pose
    axis_point_base: NDArray[np.float64]
    axis_direction_base: NDArray[np.float64]


def calibration_sim_cell(
    sensor: str = "realsense-d435",
    calibration: str = "poor",
    seed: int = 0,
    target: SphereTarget = DEFAULT_TARGET,
    cell_config: CellConfig | None = None,
) -> Cell:
    """A simulated cell (URDF arm) with ``target`` on the plate, the sensor model and calibration error named."""
    from devices.sim import make_sim_cell

    return make_sim_cell(target.mesh(), CameraConfig(sensor=sensor, calibration=calibration), cell_config, seed)


def sim_truth(cell: Cell) -> SimTruth:
    """The truth of a simulated cell (its ``errors``); ValueError for a cell without them."""
    if cell.errors is None or cell.kinematics is None:
        raise ValueError("calibration: not a simulated cell with an arm model (no drawn errors to compare with)")
    nominal = Pose.from_matrix(cell.kinematics.config.T_flange_camera_matrix)
    axis = cell.errors.T_base_axis
    return SimTruth(cell.errors.T_flange_camera_true(nominal), axis.translation.copy(), axis.rotation[:, 2].copy())


def compare(result: CalibrationResult, truth: SimTruth, nominal: Pose) -> dict[str, Any]:
    """JSON-ready: the true, the nominal and the recovered values and the errors (before: of the nominal)."""
    he_mm, he_deg = pose_error(result.T_flange_camera, truth.T_flange_camera)
    ax_mm, ax_deg = axis_error(
        result.axis_point_base, result.axis_direction_base, truth.axis_point_base, truth.axis_direction_base
    )
    before_mm, before_deg = pose_error(nominal, truth.T_flange_camera)
    axis_before_mm, axis_before_deg = axis_error(
        np.zeros(3), np.array([0.0, 0.0, 1.0]), truth.axis_point_base, truth.axis_direction_base
    )
    return {
        "true": {
            "T_flange_camera": truth.T_flange_camera.matrix.tolist(),
            "axis_point": [float(v) for v in truth.axis_point_base],
            "axis_direction": [float(v) for v in truth.axis_direction_base],
        },
        "recovered": result.to_json(),
        "hand_eye_error_mm": he_mm,
        "hand_eye_error_deg": he_deg,
        "axis_error_mm": ax_mm,
        "axis_error_deg": ax_deg,
        "nominal_error": {
            "hand_eye_mm": before_mm,
            "hand_eye_deg": before_deg,
            "axis_mm": axis_before_mm,
            "axis_deg": axis_before_deg,
        },
    }


def calibrate_sim(
    sensor: str = "realsense-d435",
    calibration: str = "poor",
    seed: int = 0,
    angle_sigma_deg: float = 0.1,
    progress: Callable[[int, CalibrationPose, Capture | None], None] | None = None,
    plate_angles_deg: tuple[float, ...] = PLATE_ANGLES_DEG,
    cell_config: CellConfig | None = None,
) -> dict[str, Any]:
    """Run the whole routine on a simulated cell and compare with its truth: :func:`compare`'s dict plus the
    seed, sensor, calibration, the drawn errors, captures, skipped poses and seconds. progress: as in
    :meth:`Calibration.run`. cell_config: the cell (its arm), default the default cell."""
    import time

    from devices.calibration.routine import Calibration

    t0 = time.perf_counter()
    cell = calibration_sim_cell(sensor, calibration, seed, cell_config=cell_config)
    routine = Calibration(cell, plate_angles_deg=plate_angles_deg)
    result = routine.run(progress, angle_sigma_deg)
    out = {
        "seed": seed,
        "sensor": sensor,
        "calibration": calibration,
        "drawn": cell.errors.summary() if cell.errors is not None else None,
        "captures": len(routine.captures),
        "skipped": [{"label": label, "reason": reason} for label, reason in routine.skipped],
    }
    out.update(compare(result, sim_truth(cell), routine.T_flange_camera_nominal))
    out["seconds"] = time.perf_counter() - t0
    return out
