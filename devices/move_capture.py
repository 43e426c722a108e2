"""Capture during moves: where the camera is at each moment of a move, and the frames a simulated cell takes there.

A move (:class:`devices.motion.Motion`) runs in phases the cell executes one after the other
(:meth:`devices.cell.Cell.move_to`):

- URDF arm: the retract trajectory (if any, plate still), then the plate's turn at ``turntable_speed_deg`` the short
  way (arm still), then the arm's trajectory (plate still); with ``Motion.overlapped`` the turn and the trajectory
  start together after the retract. The camera's nominal pose at time t is ``Rz(-angle(t)) @ FK(q(t))`` with q(t)
  the trajectory sampled as the arm plays it (linear between its points, ``JointTrajectory.sample``).
- Reach sphere: the plate's turn (camera still in the base frame), then the camera's straight travel at
  ``SPHERE_CAMERA_SPEED`` (position linear, orientation slerp) to the target.

:class:`MovePath` answers those poses for times since the move started (:func:`camera_path` for a list of times).
:class:`SimulatedMoveCapture` renders frames along a path at a rate: each frame's REPORTED pose is the nominal pose
at its stamp; the TRUE pose it is rendered from follows the sensor's timing model (``SensorModel.stamp_latency``,
``stamp_jitter``, ``exposure``): the frame was exposed around ``stamp - latency error``, and a move during the
exposure blurs it (pixels whose depths disagree across the exposure are dropped, as a stereo camera drops mixed
pixels; the others average).
"""

from __future__ import annotations

import math
from collections.abc import Callable, Iterator, Sequence
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any, Protocol

import numpy as np
from numpy.typing import NDArray
from scipy.spatial.transform import Rotation, Slerp

from devices.angles import wrap_angle
from devices.motion import SPHERE_CAMERA_SPEED, Motion, rz
from planner.types import DepthFrame, Pose

if TYPE_CHECKING:
    from devices.arm.kinematics import ArmKinematics
    from devices.calibration_error import CellErrors
    from devices.config import CameraConfig, CellConfig
    from devices.sensors import SensorModel
    from planner.types import Intrinsics


class MovingCell(Protocol):
    """What a path needs of the cell that runs the move (:class:`devices.cell.Cell`): its state before the move."""

    @property
    def kinematics(self) -> ArmKinematics | None: ...

    @property
    def config(self) -> CellConfig: ...

    @property
    def angle(self) -> float: ...

    @property
    def T_base_camera(self) -> Pose: ...


class RenderingCamera(Protocol):
    """What the frames of a move need of the simulated camera (:class:`devices.sim.SimulatedCamera`)."""

    @property
    def sensor(self) -> SensorModel: ...

    @property
    def config(self) -> CameraConfig: ...

    @property
    def intrinsics(self) -> Intrinsics: ...

    def render(self, T_table_camera: Pose) -> NDArray[np.float32]: ...

    def render_sensor(self, T_table_camera: Pose) -> NDArray[np.float32]: ...


VIEW_REACH = 0.4
"""The distance ahead of the camera at which :meth:`MovePath.speed_at` counts its turning, metres (the working
distance of a scan)."""
BLUR_SUBFRAMES = 3
"""Renders across a frame's exposure (its start, middle and end) when the sensor's exposure is > 0."""


@dataclass(frozen=True)
class MoveFrame:
    """A depth frame taken while the cell moved.

    frame: the depth as captured; ``frame.T_world_camera`` is the pose the cell REPORTS for the frame's stamp (table
    frame), what a real cell knows; the true pose may differ (the sensor's timing model, calibration errors).
    t: the frame's stamp, seconds since the move started.
    speed: how fast the view moved at the stamp (:meth:`MovePath.speed_at`, m/s), None when the cell does not say:
    a stamp error of dt misplaces the frame by about speed * dt.
    """

    frame: DepthFrame
    t: float
    speed: float | None = None

    def __post_init__(self) -> None:
        if not isinstance(self.frame, DepthFrame):
            raise ValueError(f"frame: expected a DepthFrame, got {type(self.frame).__name__}")
        if not (isinstance(self.t, int | float) and math.isfinite(self.t) and self.t >= 0):
            raise ValueError(f"t: must be a finite number of seconds >= 0, got {self.t!r}")
        if self.speed is not None and not (math.isfinite(self.speed) and self.speed >= 0):
            raise ValueError(f"speed: must be a finite number of m/s >= 0, got {self.speed!r}")


OnFrame = Callable[[MoveFrame], None]
"""What a cell calls for each frame taken during a move (``Cell.move_to(..., on_frame=...)``)."""


def capture_times(duration: float, hz: float) -> NDArray[np.float64]:
    """(K,) the stamps of frames taken at ``hz`` during a move of ``duration`` seconds: k / hz for k >= 1, strictly
    inside the move (the view before the move and the view it leads to are captured anyway). Empty for hz <= 0."""
    if not (math.isfinite(hz) and hz >= 0):
        raise ValueError(f"capture_hz: must be a finite number >= 0, got {hz!r}")
    if hz == 0 or not duration > 0:
        return np.zeros(0)
    count = math.ceil(duration * hz) - 1
    return np.arange(1, count + 1, dtype=np.float64) / hz


@dataclass(frozen=True, eq=False)
class MovePath:
    """Where the camera is during one move, from the state the move starts in.

    motion: the move. start_angle: the plate angle before it (rad). T_base_camera_start: the camera before it (the
    reach sphere's straight travel starts there). camera_pose_of: forward kinematics q (n,) -> ``T_base_camera``
    (None for the reach sphere). turn_speed: the plate's speed, rad/s.
    """

    motion: Motion
    start_angle: float
    T_base_camera_start: Pose
    camera_pose_of: Callable[[NDArray[np.float64]], Pose] | None
    turn_speed: float

    @classmethod
    def of(cls, cell: MovingCell, motion: Motion) -> MovePath:
        """The path of ``motion`` run by ``cell`` from its current state (call it before the move)."""
        if cell.kinematics is not None:
            speed = cell.kinematics.config.turntable_speed_deg
            fk: Callable[[NDArray[np.float64]], Pose] | None = cell.kinematics.camera_pose
        else:
            speed, fk = cell.config.arm.turntable_speed_deg, None
        return cls(motion, cell.angle, cell.T_base_camera, fk, math.radians(speed))

    @property
    def turn(self) -> float:
        """The plate's turn, rad (signed, the short way)."""
        return wrap_angle(self.motion.angle - self.start_angle)

    @property
    def turn_seconds(self) -> float:
        return abs(self.turn) / self.turn_speed

    @property
    def retract_seconds(self) -> float:
        return self.motion.retract.duration if self.motion.retract is not None else 0.0

    @property
    def travel_seconds(self) -> float:
        """The arm's part after the retract: the trajectory, or the reach sphere's straight travel."""
        if self.motion.trajectory is not None:
            return self.motion.trajectory.duration
        distance = float(np.linalg.norm(self.motion.T_base_camera.translation - self.T_base_camera_start.translation))
        return distance / SPHERE_CAMERA_SPEED

    @property
    def duration(self) -> float:
        """Seconds of the whole move (``Motion.duration`` for a timed motion)."""
        if self.motion.overlapped:
            return self.retract_seconds + max(self.turn_seconds, self.travel_seconds)
        return self.retract_seconds + self.turn_seconds + self.travel_seconds

    def angle_at(self, t: float) -> float:
        """The plate angle at time ``t`` (s since the move started), rad."""
        turning = t - self.retract_seconds
        if self.turn_seconds == 0 or turning <= 0:
            return self.start_angle
        return wrap_angle(self.start_angle + self.turn * min(1.0, turning / self.turn_seconds))

    def joints_at(self, t: float) -> NDArray[np.float64] | None:
        """(n,) the arm's joints at time ``t`` (None for the reach sphere)."""
        motion = self.motion
        if motion.trajectory is None:
            return None
        if motion.retract is not None and t < self.retract_seconds:
            return motion.retract.sample(t)
        arm_start = self.retract_seconds + (0.0 if motion.overlapped else self.turn_seconds)
        return motion.trajectory.sample(t - arm_start)

    def base_camera_at(self, t: float) -> Pose:
        """``T_base_camera`` at time ``t``: forward kinematics of the joints, or the sphere's straight travel."""
        q = self.joints_at(t)
        if q is not None:
            if self.camera_pose_of is None:
                raise ValueError("a joint trajectory needs the arm's forward kinematics (camera_pose_of)")
            return self.camera_pose_of(q)
        travel = self.travel_seconds
        s = 1.0 if travel == 0 else min(1.0, max(0.0, (t - self.turn_seconds) / travel))
        if s <= 0.0:
            return self.T_base_camera_start
        if s >= 1.0:
            return self.motion.T_base_camera
        a, b = self.T_base_camera_start, self.motion.T_base_camera
        rotations = Rotation.from_matrix(np.stack([a.rotation, b.rotation]))
        R = Slerp([0.0, 1.0], rotations)([s]).as_matrix()[0]
        return Pose(R, (1 - s) * a.translation + s * b.translation)

    def T_table_camera(self, t: float) -> Pose:
        """The nominal ``T_table_camera`` at time ``t`` (clamped to [0, duration])."""
        t = min(max(float(t), 0.0), self.duration)
        return rz(-self.angle_at(t)) @ self.base_camera_at(t)

    def speed_at(self, t: float, reach: float = VIEW_REACH, dt: float = 0.01) -> float:
        """How fast the view moves at time ``t`` (table frame), m/s: the camera's speed plus its turn rate times
        ``reach`` (a point that far ahead of the camera), by central differences over ``dt`` seconds."""
        a, b = self.T_table_camera(t - dt), self.T_table_camera(t + dt)
        span = min(t + dt, self.duration) - max(t - dt, 0.0)
        if span <= 0:
            return 0.0
        turn = Rotation.from_matrix(a.rotation.T @ b.rotation).magnitude()
        return float((np.linalg.norm(b.translation - a.translation) + turn * reach) / span)

    def poses(self, times: Sequence[float] | NDArray[np.float64]) -> list[Pose]:
        """The nominal ``T_table_camera`` at each time."""
        return [self.T_table_camera(float(t)) for t in np.asarray(times, dtype=np.float64).reshape(-1)]


def camera_path(cell: MovingCell, motion: Motion, times: Sequence[float] | NDArray[np.float64]) -> list[Pose]:
    """``T_table_camera`` at each time (s since the move started) along ``motion`` as ``cell`` executes it from its
    current state: retract, plate turn (or the turn overlapped with the trajectory) and the arm's trajectory, by
    forward kinematics of the trajectory's joints at t and the plate's angle at t (reach sphere: the plate turn, then
    the camera's straight travel). Call it before the move runs."""
    return MovePath.of(cell, motion).poses(times)


class SimulatedMoveCapture:
    """Renders the frames a simulated cell takes during a move.

    camera: the cell's simulated camera (its sensor's timing model and effects, its depth-noise RNG).
    errors: the cell's calibration errors (the render uses the true pose); None: none.
    seed: seeds the stamp jitter.
    """

    def __init__(self, camera: RenderingCamera, errors: CellErrors | None = None, seed: int = 0) -> None:
        self.camera = camera
        self.errors = errors
        self._rng = np.random.default_rng(seed)

    def device_state(self) -> dict[str, Any]:
        """The jitter RNG's state (JSON-ready)."""
        return {"jitter": self._rng.bit_generator.state}

    def restore_device_state(self, state: dict[str, Any]) -> None:
        self._rng.bit_generator.state = state["jitter"]

    def true_pose(self, path: MovePath, t: float) -> Pose:
        """The camera's true ``T_table_camera`` at time ``t`` (the calibration errors applied; the per-move arm and
        plate errors those of the configuration the move reaches)."""
        from devices.calibration_error import configuration_key

        t = min(max(float(t), 0.0), path.duration)
        nominal = path.base_camera_at(t)
        angle = path.angle_at(t)
        if self.errors is None or self.errors.model.is_exact:
            return rz(-angle) @ nominal
        key = configuration_key(path.motion.q, path.motion.T_base_camera)
        return self.errors.true_T_table_camera(nominal, angle, key)

    def exposure_times(self, stamp: float) -> NDArray[np.float64]:
        """(1,) or (BLUR_SUBFRAMES,) the times the frame stamped ``stamp`` was really exposed at: around
        ``stamp - latency`` (latency drawn: ``stamp_latency`` + N(0, ``stamp_jitter``)), across ``exposure``."""
        sensor = self.camera.sensor
        latency = sensor.stamp_latency
        if sensor.stamp_jitter > 0:
            latency += float(self._rng.normal(0.0, sensor.stamp_jitter))
        middle = stamp - latency
        if sensor.exposure <= 0:
            return np.array([middle])
        return middle + sensor.exposure * (np.linspace(0.0, 1.0, BLUR_SUBFRAMES) - 0.5)

    def render(self, path: MovePath, stamp: float) -> DepthFrame:
        """The frame stamped ``stamp``: rendered from the true poses across its exposure, reported at the nominal
        pose of ``stamp``."""
        camera = self.camera
        times = self.exposure_times(stamp)
        poses = [self.true_pose(path, float(t)) for t in times]
        middle = poses[len(poses) // 2]
        if camera.sensor.is_ideal:
            depth = camera.render(middle) if len(poses) == 1 else None
        else:
            depth = camera.render_sensor(middle)
        if len(poses) > 1:
            plain = np.stack([camera.render(T) for T in poses])  # (S, H, W)
            depth = blurred(plain, depth, camera.sensor.flying_jump)
        assert depth is not None
        if camera.sensor.is_ideal and camera.config.depth_noise_std > 0:  # a sensor's render added it already
            valid = depth > 0
            noise = self._rng.normal(0.0, camera.config.depth_noise_std, int(valid.sum())).astype(np.float32)
            depth[valid] += noise
            depth = np.where(depth > 0, depth, np.float32(0)).astype(np.float32)
        return DepthFrame(depth, path.T_table_camera(stamp), camera.intrinsics)

    def frames(self, path: MovePath, hz: float) -> Iterator[MoveFrame]:
        """The frames at ``hz`` along ``path`` (:func:`capture_times`), in stamp order."""
        for t in capture_times(path.duration, hz):
            yield MoveFrame(self.render(path, float(t)), float(t), path.speed_at(float(t)))


def blurred(plain: NDArray[np.float32], measured: NDArray[np.float32] | None, jump: float) -> NDArray[np.float32]:
    """(H, W) the depth of a frame exposed while the camera moved.

    plain: (S, H, W) noise-free depth at S times across the exposure (0: no return). measured: (H, W) the sensor's
    depth at the middle time (None: the ideal sensor, the average of ``plain`` is the depth). jump: a pixel whose
    depths across the exposure differ by more than this fraction of its depth (or that returns at some times only)
    is dropped (a mixed pixel); the others take the average over the exposure (``measured`` shifted by the
    average's offset from the middle render).
    """
    valid = np.all(plain > 0, axis=0)
    spread = plain.max(axis=0) - plain.min(axis=0)
    mean = plain.mean(axis=0)
    keep = valid & (spread <= jump * mean)
    if measured is None:
        out = np.where(keep, mean, np.float32(0))
    else:
        middle = plain[len(plain) // 2]
        out = np.where(keep & (measured > 0), measured + (mean - middle), np.float32(0))
    return out.astype(np.float32)
