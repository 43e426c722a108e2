"""Device configuration: the simulated camera, the cell geometry, the scanned object.

Frozen dataclasses in the style of ``planner/config.py``: every default is
documented once, at its field; bad values raise ``ValueError`` naming the field
(``camera.fx: ...``). Lengths in metres, angles in degrees (a config edge).
TOML files and the REST API use the same names, e.g. ``[camera] depth_noise_std = 0.001``;
``planner.config.from_dict(DeviceConfig, data)`` builds one from a nested dict.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Literal

from devices.arm.config import ArmConfig
from devices.calibration_error import calibration_named
from devices.sensors.presets import sensor_named
from planner.types import Intrinsics
from planner.validate import finite, integer, require


@dataclass(frozen=True)
class CameraConfig(Intrinsics):
    """The simulated depth camera: the pinhole model of :class:`planner.types.Intrinsics` (``width``,
    ``height``, ``fx``, ``fy``, ``cx``, ``cy``, with its defaults: 640 x 480, f = 610 px, about a 55 degree
    horizontal field of view, pixel centres at integer coordinates) plus a working range and noise."""

    min_depth: float = 0.1
    """Returns nearer than this (planar z-depth) are dropped (depth 0), metres."""
    max_depth: float = 1.5
    """Returns farther than this are dropped (depth 0), metres."""
    depth_noise_std: float = 0.0
    """Standard deviation of zero-mean Gaussian noise added to every depth value, metres (0 = exact)."""
    pose_noise_translation: float = 0.0
    """Std of the error of the reported camera position, per axis, metres (the render uses the true pose)."""
    pose_noise_rotation_deg: float = 0.0
    """Std of the error of the reported camera orientation, per rotation-vector component, degrees."""
    sensor: str = "ideal"
    """The depth sensor's error model, a name of ``devices.sensors.SENSORS``: 'ideal' (exact depth, the default),
    'realsense-d435', 'realsense-d405', 'structured-light' (docs/experiments/sensors.md, "Sensor models"). Its noise adds to
    ``depth_noise_std``; its range narrows [min_depth, max_depth]."""
    calibration: str = "none"
    """The cell's calibration and motion error, a name of ``devices.calibration_error.CALIBRATIONS``: 'none' (the
    default), 'typical', 'poor'. The reported pose is the nominal kinematics; the render uses the true one."""

    def __post_init__(self) -> None:
        for name in ("width", "height"):  # Intrinsics takes any whole number; a config refuses bools and strings
            v = getattr(self, name)
            require(integer(v) and v >= 1, f"camera.{name}: must be an integer >= 1, got {v!r}")
        for name in ("fx", "fy", "cx", "cy"):
            v = getattr(self, name)
            require(finite(v), f"camera.{name}: must be a finite number, got {v!r}")
        try:
            super().__post_init__()
        except ValueError as exc:
            raise ValueError(f"camera.{exc}") from None
        require(
            finite(self.min_depth) and self.min_depth >= 0, f"camera.min_depth: must be >= 0, got {self.min_depth!r}"
        )
        require(
            finite(self.max_depth) and self.max_depth > self.min_depth,
            f"camera.max_depth: must be > min_depth ({self.min_depth!r}), got {self.max_depth!r}",
        )
        for name in ("depth_noise_std", "pose_noise_translation", "pose_noise_rotation_deg"):
            v = getattr(self, name)
            require(finite(v) and v >= 0, f"camera.{name}: must be >= 0, got {v!r}")
        try:
            sensor_named(self.sensor)
            calibration_named(self.calibration)
        except ValueError as exc:
            raise ValueError(f"camera.{exc}") from None

    @property
    def intrinsics(self) -> Intrinsics:
        """The pinhole model alone (a plain :class:`Intrinsics`, as every frame of this camera carries)."""
        return Intrinsics(self.width, self.height, self.fx, self.fy, self.cx, self.cy)


@dataclass(frozen=True)
class CellConfig:
    """Geometry of the robot cell, in the base frame (lab frame, z-up, origin at the centre of the plate top)."""

    kinematics: Literal["urdf", "reach_sphere"] = "urdf"
    """'urdf': the arm of ``arm`` (the UR5 by default) with IK, collision checks and joint trajectories;
    'reach_sphere': the camera goes wherever it is within ``arm_reach`` of ``arm_base`` (for comparison)."""
    arm: ArmConfig = field(default_factory=ArmConfig)
    """The arm model (used when ``kinematics`` is 'urdf')."""
    arm_base: tuple[float, float, float] = (-0.45, 0.0, 0.0)
    """Reach sphere: position of the arm base (shoulder) in the base frame, metres. Its azimuth is where cameras
    are turned to. (The URDF arm's mount is ``arm.base``.)"""
    arm_reach: float = 0.8
    """Reach sphere: the camera can be at most this far from the arm base, metres."""
    arm_min_reach: float = 0.15
    """Reach sphere: the camera must be at least this far from the arm base, metres."""
    min_height: float = 0.01
    """The camera must be at least this high above the plate top (z = 0), metres."""
    plate_radius: float = 0.2
    """Radius of the turntable plate, metres."""
    plate_thickness: float = 0.02
    """Thickness of the plate below its top surface z = 0, metres."""
    initial_elevation_deg: float = 30.0
    """First view: elevation of the camera above the look-at point, degrees."""
    initial_azimuth_deg: float = 180.0
    """First view: azimuth of the camera in the table frame, degrees (180 = on the -x side, facing the arm)."""
    initial_distance: float = 0.55
    """First view: distance from the camera to the look-at point, metres."""
    initial_target_height: float = 0.1
    """First view: the camera looks at the point this high above the plate centre, metres."""
    move_capture_hz: float = 0.0
    """Capture during moves: depth frames taken per second while the arm and the plate move, integrated into the
    map like views (0 = off). docs/experiments/move-capture.md measures the rate."""
    move_capture_min_new: float = 0.02
    """Capture during moves: a move frame is integrated only when at least this share of its points on the object
    lies farther than one voxel from the map's occupied voxels (0: every frame)."""
    move_capture_max_speed: float = 0.8
    """Capture during moves: integrate a move frame only when the view moved slower than this at its stamp, m/s (the
    camera's speed plus its turn rate times 0.4 m; a stamp error of dt misplaces the frame by about speed * dt; the
    plate's turn alone moves it about 0.6-0.7 m/s); 0: any speed. docs/experiments/move-capture.md measured 0.8."""
    move_capture_registered: bool = False
    """Capture during moves: integrate a move frame only when ICP accepted its pose (a frame taken at speed carries
    the stamp's timing error)."""
    move_capture_wait: float = 0.1
    """Capture during moves: integrating a move's frames may outlast the move by at most this share of its
    modelled duration (frames that would make it wait longer are left out; the integration counted in the process's
    CPU seconds, so a loaded machine keeps the same frames)."""

    def __post_init__(self) -> None:
        require(
            self.kinematics in ("urdf", "reach_sphere"),
            f"cell.kinematics: 'urdf' or 'reach_sphere', got {self.kinematics!r}",
        )
        require(isinstance(self.arm, ArmConfig), "cell.arm: must be an ArmConfig")
        try:
            base = tuple(float(v) for v in self.arm_base)
        except (TypeError, ValueError):
            raise ValueError(f"cell.arm_base: must be 3 numbers, got {self.arm_base!r}") from None
        require(len(base) == 3 and finite(*base), f"cell.arm_base: must be 3 finite numbers, got {self.arm_base!r}")
        object.__setattr__(self, "arm_base", base)
        require(
            finite(self.arm_min_reach) and self.arm_min_reach >= 0,
            f"cell.arm_min_reach: must be >= 0, got {self.arm_min_reach!r}",
        )
        require(
            finite(self.arm_reach) and self.arm_reach > self.arm_min_reach,
            f"cell.arm_reach: must be > arm_min_reach ({self.arm_min_reach!r}), got {self.arm_reach!r}",
        )
        require(
            finite(self.min_height) and self.min_height >= 0, f"cell.min_height: must be >= 0, got {self.min_height!r}"
        )
        for name in ("plate_radius", "plate_thickness", "initial_distance"):
            v = getattr(self, name)
            require(finite(v) and v > 0, f"cell.{name}: must be > 0, got {v!r}")
        if self.kinematics == "urdf":
            x, y, _ = self.arm.mount
            require(
                (x * x + y * y) ** 0.5 >= self.plate_radius,
                f"cell.arm.base: {self.arm.mount} is inside the plate (radius {self.plate_radius} m); "
                "put the arm beside the turntable",
            )
        require(
            finite(self.initial_elevation_deg) and -90 < self.initial_elevation_deg <= 90,
            f"cell.initial_elevation_deg: must be in (-90, 90], got {self.initial_elevation_deg!r}",
        )
        require(
            finite(self.initial_azimuth_deg),
            f"cell.initial_azimuth_deg: must be finite, got {self.initial_azimuth_deg!r}",
        )
        require(
            finite(self.initial_target_height),
            f"cell.initial_target_height: must be finite, got {self.initial_target_height!r}",
        )
        require(
            finite(self.move_capture_hz) and 0 <= self.move_capture_hz <= 60,
            f"cell.move_capture_hz: must be in [0, 60] frames per second, got {self.move_capture_hz!r}",
        )
        require(
            finite(self.move_capture_min_new) and 0 <= self.move_capture_min_new <= 1,
            f"cell.move_capture_min_new: must be in [0, 1], got {self.move_capture_min_new!r}",
        )
        require(
            finite(self.move_capture_max_speed) and self.move_capture_max_speed >= 0,
            f"cell.move_capture_max_speed: must be >= 0 (m/s, 0: any), got {self.move_capture_max_speed!r}",
        )
        require(
            isinstance(self.move_capture_registered, bool),
            f"cell.move_capture_registered: true or false, got {self.move_capture_registered!r}",
        )
        require(
            finite(self.move_capture_wait) and self.move_capture_wait >= 0,
            f"cell.move_capture_wait: must be >= 0, got {self.move_capture_wait!r}",
        )


@dataclass(frozen=True)
class DeviceConfig:
    """The simulated devices of one session: camera, cell, and the object on the plate."""

    camera: CameraConfig = field(default_factory=CameraConfig)
    cell: CellConfig = field(default_factory=CellConfig)
    model: str = "l-block"
    """A built-in object name (see ``devices.builtins.BUILTIN_OBJECTS``) or the path of a mesh file."""
    size: float = 0.2
    """The object is scaled so its largest bounding-box extent is this, metres."""
    up: Literal["y", "z"] = "y"
    """Up axis of a mesh file ('y' for the Stanford models); built-in objects are always z-up."""
    seed: int = 0
    """Seeds the depth noise and the pose noise."""

    def __post_init__(self) -> None:
        require(isinstance(self.camera, CameraConfig), "devices.camera: must be a CameraConfig")
        require(isinstance(self.cell, CellConfig), "devices.cell: must be a CellConfig")
        require(
            isinstance(self.model, str) and self.model.strip() != "",
            f"devices.model: must be a name or path, got {self.model!r}",
        )
        require(finite(self.size) and self.size > 0, f"devices.size: must be > 0, got {self.size!r}")
        require(self.up in ("y", "z"), f"devices.up: 'y' or 'z', got {self.up!r}")
        require(
            integer(self.seed) and self.seed >= 0,
            f"devices.seed: must be an integer >= 0, got {self.seed!r}",
        )


ARM_CHOICES_HELP = (
    "a preset (ur5, ur10, panda, xarm7, z1: 'nbv arms'), the path of a URDF file, 'urdf' (= ur5) or 'reach_sphere'"
)
"""What ``--arm`` takes, for help texts."""


def cell_with_arm(cell: CellConfig, arm: str | None) -> CellConfig:
    """``cell`` with the arm ``arm`` names (``--arm``): a preset name or the path of a URDF file (a URDF arm with the
    preset's, or a file's, defaults; the other arm settings of ``cell.arm`` are kept), 'urdf' (the arm of
    ``cell.arm``, the UR5 unless configured), 'reach_sphere' (no arm model), None (``cell`` unchanged).
    ValueError naming ``--arm`` for a name that is neither a preset nor a file."""
    import dataclasses
    from pathlib import Path

    from devices.arm.presets import PRESETS

    if arm is None:
        return cell
    if arm == "reach_sphere":
        return dataclasses.replace(cell, kinematics="reach_sphere")
    if arm == "urdf":
        return dataclasses.replace(cell, kinematics="urdf")
    if arm not in PRESETS and not Path(arm).expanduser().is_file():
        raise ValueError(f"--arm: {arm!r} is no preset ({', '.join(PRESETS)}) and no URDF file")
    changed = cell.arm if cell.arm.urdf == arm else dataclasses.replace(cell.arm, urdf=arm)
    return dataclasses.replace(cell, kinematics="urdf", arm=changed)
