"""Calibration of a cell: the hand-eye transform ``T_flange_camera`` and the turntable axis, from a depth camera's
views of a sphere target on the plate (docs/experiments/calibration.md; docs/hardware.md, "Commissioning a
cell").

- ``target``   SphereTarget, DEFAULT_TARGET: the spheres, their mesh and box
- ``spheres``  fit_sphere, find_spheres, SphereFit: least-squares sphere fits in a frame
- ``poses``    CalibrationPose, calibration_poses: the poses a person approves
- ``fit``      estimate, check_captures, ErrorBudget: OpenCV hand-eye start, scipy least-squares refinement, covariance
- ``result``   Capture, CalibrationResult, CalibrationError, pose_error, axis_error
- ``routine``  Calibration: pose list, preview, capture step, estimate on a cell
- ``cellwrite`` write_calibration: the result into the cell file, the old one kept as a backup
- ``sim``      calibration_sim_cell, sim_truth, compare: the simulated cell and its truth
"""

from devices.calibration.cellwrite import calibrated_cell_text, write_calibration
from devices.calibration.fit import ErrorBudget, check_captures, estimate
from devices.calibration.poses import CalibrationPose, calibration_poses
from devices.calibration.result import CalibrationError, CalibrationResult, Capture, axis_error, pose_error
from devices.calibration.routine import Calibration
from devices.calibration.sim import SimTruth, calibrate_sim, calibration_sim_cell, compare, sim_truth
from devices.calibration.spheres import SphereFit, find_spheres, fit_sphere
from devices.calibration.target import DEFAULT_TARGET, SphereTarget

__all__ = [
    "DEFAULT_TARGET",
    "Calibration",
    "CalibrationError",
    "CalibrationPose",
    "CalibrationResult",
    "Capture",
    "ErrorBudget",
    "SimTruth",
    "SphereFit",
    "SphereTarget",
    "axis_error",
    "calibrate_sim",
    "calibrated_cell_text",
    "calibration_poses",
    "calibration_sim_cell",
    "check_captures",
    "compare",
    "estimate",
    "find_spheres",
    "fit_sphere",
    "pose_error",
    "sim_truth",
    "write_calibration",
]
