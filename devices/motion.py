"""How the cell reaches a view: :class:`Motion` (plate angle, arm target, trajectory, duration) and ``rz``.

Frames as in devices/cell.py: ``T_base_camera = Rz(theta) @ T_table_camera`` with theta the plate angle.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import numpy as np

from devices.trajectory import JointTrajectory
from planner.types import Pose

SPHERE_CAMERA_SPEED = 0.25
"""Reach sphere: the camera's straight-line speed assumed for a move's duration estimate, m/s."""


def rz(theta: float) -> Pose:
    """``Rz(theta)``: rotation by ``theta`` radians about +z (counter-clockwise seen from above)."""
    c, s = math.cos(theta), math.sin(theta)
    return Pose(np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]]), np.zeros(3))


@dataclass(frozen=True, eq=False)
class Motion:
    """How the cell reaches a view: turntable ``angle`` (rad, in (-pi, pi]) and the arm's ``T_base_camera``.

    With a URDF arm also: ``q`` (n,) the joint target, ``trajectory`` the timed joint trajectory from the
    current configuration, ``duration`` seconds of the whole move (plate turn + trajectory; for the reach
    sphere: the plate turn plus the camera's straight travel at ``SPHERE_CAMERA_SPEED``), ``path_method``
    ('straight' or 'rrt_connect') and ``planning_seconds``.
    """

    angle: float
    T_base_camera: Pose
    q: np.ndarray | None = None
    trajectory: JointTrajectory | None = None
    duration: float = 0.0
    path_method: str = ""
    planning_seconds: float = 0.0
    retract: JointTrajectory | None = None
    """URDF arm: the trajectory to the retracted configuration that runs before the plate turns, when the turn
    would sweep the object's box into the standing arm (None: the arm stands still while the plate turns)."""
    overlapped: bool = False
    """URDF arm: the plate turns while the arm runs ``trajectory`` (``ArmConfig.turn_while_moving``, the whole path
    clear of the turning object); ``duration`` then counts the longer of the two, not their sum."""
    timed: bool = True
    """False when the cell does not model how long its moves take (a replay: the views were taken already), so
    ``duration`` says nothing about the move."""

    @property
    def path_length(self) -> float:
        """Length of the joint path, radians (0 without a trajectory)."""
        return self.trajectory.path_length() if self.trajectory is not None else 0.0

    def to_json(self) -> dict[str, Any]:
        """The metrics of a move: plate angle, joints, ``T_base_camera``, joint path length and duration."""
        return {
            "plate_angle": float(self.angle),
            "joints": None if self.q is None else [float(v) for v in self.q],
            "T_base_camera": self.T_base_camera.to_dict(),
            "path_length": self.path_length,
            "move_duration": float(self.duration),
            "path_method": self.path_method or None,
            "motion_planning_seconds": float(self.planning_seconds),
            "retracted": self.retract is not None,
            "turn_overlapped": self.overlapped,
        }
