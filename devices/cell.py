"""The robot cell: a camera on an arm and an object on a turntable, seen from the planner's world.

Frames (all z-up, metres, radians):

- ``base``: the lab frame. Origin at the centre of the plate's top surface, z up.
  The arm base (shoulder) is at ``CellConfig.arm_base``; the arm moves the
  camera to ``T_base_camera``.
- ``table``: fixed to the plate, rotating with it. ``T_base_table = Rz(theta)``
  with theta the turntable angle. The planner's ``world`` is the table frame, so
  ``T_table_camera = Rz(-theta) @ T_base_camera``.
- camera: OpenCV axes (+z forward, +x right, +y down).

A planned view ``T_table_camera`` is reached by turning the plate so the
camera's azimuth about the turntable axis equals the azimuth of the arm base
(the arm then works in its own vertical plane through the axis) and moving the
arm to ``T_base_camera = Rz(theta) @ T_table_camera``.

``devices.sim.make_sim_cell`` builds a Cell of simulated devices.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import numpy as np
from numpy.typing import NDArray
from scipy.spatial.transform import Rotation

from devices.config import CellConfig
from devices.protocols import Arm, Camera, Turntable, UnreachableError
from planner.types import DepthFrame, Intrinsics, Pose


def rz(theta: float) -> Pose:
    """``Rz(theta)``: rotation by ``theta`` radians about +z (counter-clockwise seen from above)."""
    c, s = math.cos(theta), math.sin(theta)
    return Pose(np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]]), np.zeros(3))


def wrap_angle(angle: float) -> float:
    """``angle`` wrapped to (-pi, pi]."""
    a = math.remainder(angle, 2 * math.pi)
    return math.pi if a == -math.pi else a


@dataclass(frozen=True, eq=False)
class Motion:
    """How the cell reaches a view: turntable ``angle`` (rad, in (-pi, pi]) and the arm's ``T_base_camera``."""

    angle: float
    T_base_camera: Pose


class Cell:
    """A camera, an arm and a turntable working together in the table frame.

    camera, arm, turntable: any objects satisfying the protocols in ``devices.protocols``.
    config: the cell geometry (arm base, reach, plate).
    pose_noise_translation: std of the error of the reported camera position, per axis, metres.
    pose_noise_rotation_deg: std of the error of the reported orientation, per rotation-vector component, degrees.
    seed: seeds the pose noise.
    """

    def __init__(
        self,
        camera: Camera,
        arm: Arm,
        turntable: Turntable,
        config: CellConfig | None = None,
        *,
        pose_noise_translation: float = 0.0,
        pose_noise_rotation_deg: float = 0.0,
        seed: int = 0,
    ) -> None:
        for name, value in (
            ("pose_noise_translation", pose_noise_translation),
            ("pose_noise_rotation_deg", pose_noise_rotation_deg),
        ):
            if not (math.isfinite(value) and value >= 0):
                raise ValueError(f"{name}: must be >= 0, got {value!r}")
        self.camera = camera
        self.arm = arm
        self.turntable = turntable
        self.config = config if config is not None else CellConfig()
        self.pose_noise_translation = float(pose_noise_translation)
        self.pose_noise_rotation = math.radians(pose_noise_rotation_deg)
        self._rng = np.random.default_rng(seed)
        self._arm_base = np.asarray(self.config.arm_base, dtype=np.float64)

    # ------------------------------------------------------------------ geometry

    @property
    def intrinsics(self) -> Intrinsics:
        return self.camera.intrinsics

    @property
    def angle(self) -> float:
        """The turntable angle theta, radians."""
        return self.turntable.angle

    @property
    def pose(self) -> Pose:
        """The true (noise-free) ``T_table_camera`` from the arm pose and the turntable angle."""
        return rz(-self.turntable.angle) @ self.arm.pose

    def plan_motion(self, T_table_camera: Pose) -> Motion:
        """The turntable angle and arm pose that put the camera at ``T_table_camera``.

        theta turns the camera's azimuth onto the arm base's azimuth; a camera on
        the turntable axis keeps the current angle. Raises UnreachableError (with
        the numbers) when the camera would be below ``min_height`` above the plate
        top, or farther than ``arm_reach`` / nearer than ``arm_min_reach`` from the arm base.
        """
        if not isinstance(T_table_camera, Pose):
            raise ValueError(f"T_table_camera: expected a Pose, got {type(T_table_camera).__name__}")
        x, y, z = T_table_camera.translation
        cfg = self.config
        if z < cfg.min_height:
            raise UnreachableError(
                f"unreachable: camera at height {z:.3f} m is below the plate top + clearance ({cfg.min_height:.3f} m)"
            )
        if math.hypot(x, y) < 1e-9:
            theta = wrap_angle(self.turntable.angle)
        else:
            arm_azimuth = math.atan2(self._arm_base[1], self._arm_base[0])
            theta = wrap_angle(arm_azimuth - math.atan2(y, x))
        T_base_camera = rz(theta) @ T_table_camera
        distance = float(np.linalg.norm(T_base_camera.translation - self._arm_base))
        if distance > cfg.arm_reach:
            raise UnreachableError(
                f"unreachable: camera {distance:.3f} m from the arm base, beyond arm_reach {cfg.arm_reach:.3f} m"
            )
        if distance < cfg.arm_min_reach:
            raise UnreachableError(
                f"unreachable: camera {distance:.3f} m from the arm base, "
                f"nearer than arm_min_reach {cfg.arm_min_reach:.3f} m"
            )
        return Motion(theta, T_base_camera)

    def is_reachable(self, T_table_camera: Pose) -> bool:
        """Whether :meth:`plan_motion` succeeds for this view (closed form, no Pose built).

        plan_motion turns the camera onto the arm base's azimuth, so its distance to
        the base is that of two points in one vertical half-plane.
        """
        x, y, z = T_table_camera.translation
        cfg = self.config
        if z < cfg.min_height:
            return False
        base_radial = math.hypot(self._arm_base[0], self._arm_base[1])
        distance = math.hypot(math.hypot(x, y) - base_radial, z - self._arm_base[2])
        return cfg.arm_min_reach <= distance <= cfg.arm_reach

    def initial_pose(self) -> Pose:
        """``T_table_camera`` of the first view: at ``initial_elevation_deg`` / ``initial_azimuth_deg`` /
        ``initial_distance`` about the point ``initial_target_height`` above the plate centre, looking at it.
        """
        cfg = self.config
        e, a = math.radians(cfg.initial_elevation_deg), math.radians(cfg.initial_azimuth_deg)
        target = np.array([0.0, 0.0, cfg.initial_target_height])
        eye = target + cfg.initial_distance * np.array(
            [math.cos(e) * math.cos(a), math.cos(e) * math.sin(a), math.sin(e)]
        )
        return Pose.look_at(eye, target)

    # ------------------------------------------------------------------ actions

    def move_to(self, T_table_camera: Pose) -> Motion:
        """Turn the plate, then move the arm, so the camera is at ``T_table_camera``.

        Checks reachability first: an unreachable view raises UnreachableError and
        moves nothing. A device fault (DeviceError) after the turntable moved leaves
        the plate at its new angle.
        """
        motion = self.plan_motion(T_table_camera)
        self.turntable.rotate_to(motion.angle)
        self.arm.move_to(motion.T_base_camera)
        return motion

    def capture(self) -> DepthFrame:
        """A depth image with ``T_world_camera`` = the camera pose in the table frame.

        The pose is ``Rz(-theta) @ arm.pose``, perturbed by the configured pose noise
        (a fresh draw per capture); the image itself was taken from the true pose.
        """
        frame = self.camera.capture()
        return frame.with_pose(self._perturb(self.pose))

    def device_state(self) -> dict[str, Any]:
        """What a resumed session needs to continue exactly: the pose-noise RNG state and the camera's
        ``device_state()`` (its noise RNG, or a replay camera's position), JSON-ready."""
        state: dict[str, Any] = {"pose_noise": self._rng.bit_generator.state}
        camera_state = getattr(self.camera, "device_state", None)
        if callable(camera_state):
            state["camera"] = camera_state()
        return state

    def restore_device_state(self, state: dict[str, Any]) -> None:
        """Undo :meth:`device_state`: the next capture draws the noise it would have drawn. ValueError if malformed."""
        try:
            if "pose_noise" in state:
                self._rng.bit_generator.state = state["pose_noise"]
            restore = getattr(self.camera, "restore_device_state", None)
            if "camera" in state and callable(restore):
                restore(state["camera"])
        except (TypeError, KeyError, ValueError) as exc:
            raise ValueError(f"device state: cannot restore ({exc})") from None

    def _perturb(self, pose: Pose) -> Pose:
        if self.pose_noise_translation == 0 and self.pose_noise_rotation == 0:
            return pose
        dt: NDArray[np.float64] = (
            self._rng.normal(0.0, self.pose_noise_translation, 3) if self.pose_noise_translation else np.zeros(3)
        )
        rotvec = self._rng.normal(0.0, self.pose_noise_rotation, 3) if self.pose_noise_rotation else np.zeros(3)
        dR = Rotation.from_rotvec(rotvec).as_matrix()
        return Pose(pose.rotation @ dR, pose.translation + dt)
