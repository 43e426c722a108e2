"""What a device driver implements, and the errors devices raise.

A real camera, arm or turntable only has to provide these few methods and
properties (structural typing: no base class needed). The :class:`devices.cell.Cell`
combines one of each into the planner's view of the world.

Frames (see ``devices/cell.py``): the arm works in the ``base`` frame (lab frame,
z-up, origin at the centre of the plate top); the turntable angle rotates the
``table`` frame (the planner's world) about the base z axis.
"""

from __future__ import annotations

from typing import Protocol, runtime_checkable

import numpy as np
from numpy.typing import NDArray

from devices.trajectory import JointTrajectory
from planner.types import DepthFrame, Intrinsics, Pose


class DeviceError(Exception):
    """A device could not do what it was asked (base class of all device errors)."""


class UnreachableError(DeviceError):
    """The arm cannot put the camera at the requested pose.

    ``reason`` is a short code: ``no_ik`` (out of the workspace), ``joint_limit``, ``collision:<link>:<obstacle>``,
    ``no_path`` (no collision-free motion in the planning time), or ``reach`` (the reach-sphere cell's
    distance and height test).
    """

    def __init__(self, message: str, reason: str = "reach") -> None:
        super().__init__(message)
        self.reason = reason

    def __reduce__(self) -> tuple[type, tuple[str, str]]:  # keeps the reason across worker processes
        return (type(self), (str(self), self.reason))


class CaptureError(DeviceError):
    """The camera did not deliver a depth image."""


@runtime_checkable
class Camera(Protocol):
    """A depth camera.

    ``capture`` returns the depth image of the current view. The camera does not
    know where it is: the ``T_world_camera`` of the returned frame may be the
    identity; :meth:`devices.cell.Cell.capture` replaces it with the pose from the
    arm and the turntable. Raises :class:`CaptureError` when no image arrives.
    """

    @property
    def intrinsics(self) -> Intrinsics:
        """The pinhole model of every image this camera returns."""
        ...

    def capture(self) -> DepthFrame:
        """One depth image, (height, width) float32 planar z-depth in metres, 0 = no return."""
        ...


@runtime_checkable
class Arm(Protocol):
    """A robot arm carrying the camera (hand-eye calibrated: it moves the camera, not the flange).

    ``move_to`` blocks until the camera is at ``T_base_camera`` (camera pose in
    the base frame, OpenCV camera axes). Raises :class:`UnreachableError` when the
    pose cannot be reached, :class:`DeviceError` for other faults.
    """

    @property
    def pose(self) -> Pose:
        """``T_base_camera``, the current camera pose in the base frame."""
        ...

    def move_to(self, T_base_camera: Pose) -> None: ...


@runtime_checkable
class Turntable(Protocol):
    """A turntable rotating the object about the base z axis.

    ``angle`` (radians, counter-clockwise seen from above) is theta in
    ``T_base_table = Rz(theta)``. ``rotate_to`` blocks until the plate is there.
    """

    @property
    def angle(self) -> float:
        """Current plate angle, radians."""
        ...

    def rotate_to(self, angle: float) -> None: ...


@runtime_checkable
class JointArm(Protocol):
    """A robot arm as hardware sees it: it executes joint trajectories and reports its joints.

    Inverse kinematics, collision checks and motion planning happen on our side (``devices/``), so
    every arm, simulated or real, gets the same checks; a driver only executes what it is sent.
    ``execute`` blocks until the trajectory's end (or raises :class:`DeviceError` with the
    controller's reason, the arm then stopped where it was); ``stop`` halts a running motion at once
    (callable from another thread) and is harmless when nothing moves.
    """

    @property
    def joint_names(self) -> tuple[str, ...]:
        """The joints, in the order of every configuration vector."""
        ...

    def joint_positions(self) -> NDArray[np.float64]:
        """(n,) the current configuration, radians."""
        ...

    def execute(self, trajectory: JointTrajectory) -> None: ...

    def stop(self) -> None: ...
