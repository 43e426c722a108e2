"""The poses a calibration visits: the target seen from varied tilts and rolls, at several plate angles.

Hand-eye needs the flange to rotate about different axes between captures (about one axis only, the offset along
it stays unknown); the axis needs the plate at several angles. Every view looks at the target's middle from
``distance``; per plate angle the views vary the elevation, the azimuth about the plate (one of the arm's
``plate_offsets_deg``, so the plate angle asked for is one the arm's planner tries) and the roll about the optical
axis. A person approves the list before anything moves (:class:`devices.calibration.routine.Calibration`).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import numpy as np

from devices.calibration.target import SphereTarget
from planner.types import Pose

PLATE_ANGLES_DEG = (0.0, 60.0, 120.0, 180.0, -120.0, -60.0)
"""Plate angles of the default pose list, degrees."""
VIEWS = (
    (0.0, 30.0, 0.0),
    (30.0, 45.0, 60.0),
    (-30.0, 45.0, -60.0),
    (0.0, 60.0, 90.0),
    (60.0, 40.0, -45.0),
    (-60.0, 40.0, 45.0),
)
"""Per plate angle: (azimuth offset from the arm's side, elevation, roll about the optical axis), degrees. Large
rolls and tilts: the hand-eye translation is found only as well as the rotations between captures are large (with
16 captures of rolls up to 40 degrees the UR5's 0.3 mm repeatability gave up to 1.1 mm; with these 36, 0.5 mm)."""
DISTANCE = 0.5
"""Camera to the target's middle, metres."""


@dataclass(frozen=True, eq=False)
class CalibrationPose:
    """One pose to visit: the plate at ``plate_angle`` (rad), the camera at ``T_table_camera`` (plate frame, the
    planner's world). label: a short name (``a090-e50-r25``)."""

    label: str
    plate_angle: float
    T_table_camera: Pose

    @property
    def T_base_camera(self) -> Pose:
        """Where the camera goes in the base frame: ``Rz(plate_angle) @ T_table_camera``."""
        c, s = math.cos(self.plate_angle), math.sin(self.plate_angle)
        return Pose(np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]]), np.zeros(3)) @ self.T_table_camera

    def to_json(self) -> dict[str, Any]:
        return {
            "label": self.label,
            "plate_angle_deg": math.degrees(self.plate_angle),
            "T_table_camera": self.T_table_camera.to_dict(),
        }


def calibration_poses(
    target: SphereTarget,
    arm_azimuth: float,
    plate_angles_deg: tuple[float, ...] = PLATE_ANGLES_DEG,
    views: tuple[tuple[float, float, float], ...] = VIEWS,
    distance: float = DISTANCE,
) -> list[CalibrationPose]:
    """The pose list: for each plate angle, each view (azimuth offset, elevation, roll in degrees) looking at the
    target's middle from ``distance``, on the arm's side (``arm_azimuth``, rad: the arm mount's azimuth about the
    plate centre)."""
    if distance <= 0:
        raise ValueError(f"distance: must be > 0, got {distance!r}")
    middle = target.centre
    poses: list[CalibrationPose] = []
    for angle_deg in plate_angles_deg:
        theta = math.radians(angle_deg)
        c, s = math.cos(-theta), math.sin(-theta)
        R_table_base = np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])
        middle_base = R_table_base.T @ middle
        for offset, elevation, roll in views:
            a, e = arm_azimuth + math.radians(offset), math.radians(elevation)
            eye_base = middle_base + distance * np.array(
                [math.cos(e) * math.cos(a), math.cos(e) * math.sin(a), math.sin(e)]
            )
            T_base_camera = Pose.look_at(eye_base, middle_base)
            cr, sr = math.cos(math.radians(roll)), math.sin(math.radians(roll))
            rolled = T_base_camera.rotation @ np.array([[cr, -sr, 0.0], [sr, cr, 0.0], [0.0, 0.0, 1.0]])
            T_table_camera = Pose(R_table_base @ rolled, R_table_base @ T_base_camera.translation)
            label = f"a{angle_deg:+04.0f}-o{offset:+03.0f}-e{elevation:02.0f}-r{roll:+03.0f}"
            poses.append(CalibrationPose(label, theta, T_table_camera))
    return poses
