"""What a calibration measures and what it found: one capture's sphere centres, the estimate with its uncertainty."""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import numpy as np
from numpy.typing import NDArray
from scipy.spatial.transform import Rotation

from planner.types import Pose


class CalibrationError(ValueError):
    """The captures cannot give a calibration (too few, degenerate poses, the target not seen): one line saying
    what is missing."""


@dataclass(frozen=True, eq=False)
class Capture:
    """One calibration capture. T_base_flange: the flange pose the arm's kinematics report (base frame).
    plate_angle: the turntable angle reported, rad. centres_camera: (K, 3) float64 the fitted sphere centres in the
    camera frame, NaN rows for spheres not seen. fit_rms: (K,) the sphere fits' RMS residuals, metres (NaN: not
    seen). label: the pose's name."""

    T_base_flange: Pose
    plate_angle: float
    centres_camera: NDArray[np.float64]
    fit_rms: NDArray[np.float64]
    label: str = ""

    @property
    def seen(self) -> NDArray[np.bool_]:
        """(K,) which spheres were fitted."""
        return np.all(np.isfinite(self.centres_camera), axis=1)


@dataclass(frozen=True, eq=False)
class CalibrationResult:
    """The estimate. T_flange_camera: the hand-eye transform. axis_point_base: (3,) where the turntable axis
    crosses the plate-top plane z = 0, base frame. axis_direction_base: (3,) its unit direction (up).
    centres_table: (K, 3) the sphere centres in the plate frame. *_std: one standard deviation from the
    covariance (devices/calibration/fit.py: the residuals' plus the error budget's; hand-eye: position in mm,
    rotation in degrees, as the norm of the per-axis deviations; axis: point in mm, direction in degrees). residuals_mm: (C,) RMS of each capture's centre residuals,
    mm. rms_mm: over all. T_flange_camera_initial: what OpenCV's ``calibrateHandEye`` gave before the refinement."""

    T_flange_camera: Pose
    axis_point_base: NDArray[np.float64]
    axis_direction_base: NDArray[np.float64]
    centres_table: NDArray[np.float64]
    hand_eye_std_mm: float
    hand_eye_std_deg: float
    axis_std_mm: float
    axis_std_deg: float
    residuals_mm: NDArray[np.float64]
    rms_mm: float
    labels: tuple[str, ...]
    T_flange_camera_initial: Pose
    hand_eye_bound95_mm: float = math.nan
    """95 % of such calibrations' hand-eye position errors are below this, mm (the quantile of the error's norm
    under the estimate's covariance); likewise the rotation's (degrees) and the axis' (mm, degrees)."""
    hand_eye_bound95_deg: float = math.nan
    axis_bound95_mm: float = math.nan
    axis_bound95_deg: float = math.nan

    @property
    def axis_tilt_deg(self) -> float:
        """The axis' angle from the base frame's vertical, degrees."""
        return math.degrees(math.acos(min(1.0, float(self.axis_direction_base[2]))))

    def to_json(self) -> dict[str, Any]:
        """JSON-ready: the estimate, its uncertainty and the residual per capture."""
        R = Rotation.from_matrix(self.T_flange_camera.rotation)
        return {
            "T_flange_camera": self.T_flange_camera.matrix.tolist(),
            "hand_eye_translation": [float(v) for v in self.T_flange_camera.translation],
            "hand_eye_rotation_deg": [float(v) for v in R.as_euler("xyz", degrees=True)],
            "axis_point": [float(v) for v in self.axis_point_base],
            "axis_direction": [float(v) for v in self.axis_direction_base],
            "axis_tilt_deg": self.axis_tilt_deg,
            "hand_eye_std_mm": self.hand_eye_std_mm,
            "hand_eye_std_deg": self.hand_eye_std_deg,
            "axis_std_mm": self.axis_std_mm,
            "axis_std_deg": self.axis_std_deg,
            "hand_eye_bound95_mm": self.hand_eye_bound95_mm,
            "hand_eye_bound95_deg": self.hand_eye_bound95_deg,
            "axis_bound95_mm": self.axis_bound95_mm,
            "axis_bound95_deg": self.axis_bound95_deg,
            "rms_mm": self.rms_mm,
            "residuals_mm": {label: float(r) for label, r in zip(self.labels, self.residuals_mm, strict=True)},
        }


def pose_error(T_estimate: Pose, T_true: Pose) -> tuple[float, float]:
    """(position error mm, rotation error degrees) of an estimated transform against the true one."""
    dt = float(np.linalg.norm(T_estimate.translation - T_true.translation)) * 1000
    dR = Rotation.from_matrix(T_true.rotation.T @ T_estimate.rotation).magnitude()
    return dt, math.degrees(float(dR))


def axis_error(
    point: NDArray[np.float64],
    direction: NDArray[np.float64],
    point_true: NDArray[np.float64],
    direction_true: NDArray[np.float64],
) -> tuple[float, float]:
    """(mm between the two axes' crossings of the plate top z = 0, degrees between their directions)."""
    d, dt = direction / np.linalg.norm(direction), direction_true / np.linalg.norm(direction_true)
    angle = math.degrees(math.acos(min(1.0, abs(float(d @ dt)))))
    return float(np.linalg.norm(np.asarray(point)[:2] - np.asarray(point_true)[:2])) * 1000, angle
