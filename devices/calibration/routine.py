"""The calibration routine on a cell: the pose list (to approve), one capture step per pose, the estimate.

A phase of its own before any scan: the target stands on the plate, the arm visits the approved poses, each frame's
spheres are fitted (:mod:`devices.calibration.spheres`, where the nominal calibration predicts them), and
:func:`devices.calibration.fit.estimate` turns the captures into the hand-eye transform and the axis. The cell
must have an arm model (``CellConfig.kinematics == 'urdf'``): the flange pose is its forward kinematics of the
joints the arm reports.
"""

from __future__ import annotations

import math
from collections.abc import Callable

import numpy as np

from devices.calibration.fit import estimate
from devices.calibration.poses import PLATE_ANGLES_DEG, CalibrationPose, calibration_poses
from devices.calibration.result import CalibrationError, CalibrationResult, Capture
from devices.calibration.spheres import find_spheres
from devices.calibration.target import DEFAULT_TARGET, SphereTarget
from devices.cell import Cell, Motion, rz
from devices.protocols import UnreachableError
from planner.types import Pose


class Calibration:
    """Calibrate ``cell`` with ``target`` on its plate. poses: the list to visit (default
    :func:`calibration_poses` on the arm's side, at ``plate_angles_deg``). ``captures`` grows with each :meth:`capture`; ``skipped`` holds
    (label, reason) of the poses that could not be reached or saw no sphere."""

    def __init__(
        self,
        cell: Cell,
        target: SphereTarget = DEFAULT_TARGET,
        poses: list[CalibrationPose] | None = None,
        plate_angles_deg: tuple[float, ...] = PLATE_ANGLES_DEG,
    ) -> None:
        if cell.kinematics is None:
            raise CalibrationError("calibration: the cell has no arm model (cell.kinematics = 'urdf' is needed)")
        self.cell = cell
        self.target = target
        mount = cell.kinematics.model.T_base_mount.translation
        self.poses: list[CalibrationPose] = (
            poses
            if poses is not None
            else calibration_poses(target, math.atan2(mount[1], mount[0]), plate_angles_deg=plate_angles_deg)
        )
        self.captures: list[Capture] = []
        self.skipped: list[tuple[str, str]] = []
        cell.set_object_box(target.box())

    @property
    def T_flange_camera_nominal(self) -> Pose:
        """The hand-eye transform the cell uses now (its arm model's)."""
        assert self.cell.kinematics is not None
        return Pose.from_matrix(self.cell.kinematics.config.T_flange_camera_matrix)

    def preview(self, index: int) -> Motion:
        """The move to pose ``index`` from the current state (plate angle, joints, trajectory), for a person to see
        before approving; UnreachableError when there is none. Moves nothing."""
        pose = self.poses[index]
        return self.cell.plan_motion(pose.T_table_camera, pose.plate_angle)

    def capture(self, index: int) -> Capture | None:
        """Move to pose ``index``, take a frame, fit the spheres: the Capture (appended to ``captures``), or None
        (the pose appended to ``skipped`` with the reason) when it is unreachable or no sphere was seen."""
        pose = self.poses[index]
        try:
            self.cell.move_to(pose.T_table_camera, pose.plate_angle)
        except UnreachableError as exc:
            self.skipped.append((pose.label, str(exc)))
            return None
        frame = self.cell.camera.capture()
        capture = self.measure(frame.points_camera, pose.label)
        if not capture.seen.any():
            self.skipped.append((pose.label, "no sphere of the target seen"))
            return None
        self.captures.append(capture)
        return capture

    def measure(self, points_camera: np.ndarray, label: str = "") -> Capture:
        """The Capture of a frame's (N, 3) camera-frame points taken at the cell's current state."""
        assert self.cell.kinematics is not None
        kinematics = self.cell.kinematics
        q = self.cell.arm.joint_positions()
        T_base_flange = kinematics.model.frame_pose(kinematics.config.flange, q)
        angle = float(self.cell.turntable.angle)
        T_camera_table = (T_base_flange @ self.T_flange_camera_nominal).inverse() @ rz(angle)
        predicted = T_camera_table.apply(self.target.centres_table)
        fits = find_spheres(points_camera, predicted, self.target.radius)
        centres = np.array([f.centre if f is not None else [np.nan] * 3 for f in fits], dtype=np.float64)
        rms = np.array([f.rms if f is not None else np.nan for f in fits], dtype=np.float64)
        return Capture(T_base_flange, angle, centres, rms, label)

    def run(
        self,
        progress: Callable[[int, CalibrationPose, Capture | None], None] | None = None,
        angle_sigma_deg: float = 0.1,
    ) -> CalibrationResult:
        """Every pose in turn (:meth:`capture`), then :meth:`estimate`. progress(index, pose, capture or None)."""
        for i, pose in enumerate(self.poses):
            capture = self.capture(i)
            if progress is not None:
                progress(i, pose, capture)
        return self.estimate(angle_sigma_deg)

    def estimate(self, angle_sigma_deg: float = 0.1) -> CalibrationResult:
        """:func:`devices.calibration.fit.estimate` of the captures so far (CalibrationError naming the skipped
        poses when there is none)."""
        if not self.captures:
            why = "; ".join(f"{label}: {reason}" for label, reason in self.skipped[:3])
            raise CalibrationError(
                f"calibration: no captures ({len(self.skipped)} poses skipped{': ' if why else ''}{why})"
            )
        return estimate(self.captures, self.target, angle_sigma_deg)
