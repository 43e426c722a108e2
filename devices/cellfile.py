"""The cell file: which camera, arm and turntable a lab has, how they are mounted, and what they may do.

One TOML file (other top-level tables, e.g. the planner's, are left to their readers)::

    [devices]
    allow_auto = false            # auto mode on real hardware needs this true

    [devices.camera]
    driver = "realsense"          # or "sim", "replay"
    width = 848
    height = 480
    filters = ["spatial", "temporal"]
    noise_model = "realsense-d435"  # what the planner assumes of its noise (default "ideal")

    [devices.arm]
    driver = "ur"
    host = "192.168.1.10"
    speed_fraction = 0.25
    max_joint_speed_deg = 60

    [devices.turntable]
    driver = "grbl"
    port = "/dev/ttyUSB0"

    [devices.hand_eye]            # T_flange_camera: the camera's optical frame on the arm's flange
    translation = [0.0, 0.05, 0.04]
    rotation_deg = [0.0, 0.0, 90.0]

    [devices.arm_base]            # T_base_armbase: the arm's base frame in the cell (plate-centre) frame
    translation = [-0.45, 0.0, 0.0]
    rotation_deg = [0.0, 0.0, 0.0]

    [devices.turntable_axis]      # optional: the plate's measured axis (nbv calibrate --write), base frame
    direction = [0.0012, -0.0008, 1.0]

Each device section's ``driver`` picks a driver of :mod:`devices.drivers.registry`; its other keys are
that driver's config fields (documented at the field). Rotations are extrinsic x-y-z angles (roll, pitch,
yaw about the fixed axes), degrees, or ``quaternion_wxyz``. Relative file paths are taken from the
cell file's folder. Every error is one line naming the field (``devices.arm.speed_fraction: ...``).
"""

from __future__ import annotations

import dataclasses
import math
import tomllib
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import NDArray
from scipy.spatial.transform import Rotation

from devices.drivers.registry import KINDS, REGISTRY, Kind, driver_names, resolve_paths
from planner.types import Pose
from planner.validate import finite

POSE_SECTIONS = ("hand_eye", "arm_base")
TOP_KEYS = (*KINDS, *POSE_SECTIONS, "turntable_axis", "allow_auto", "move_capture_hz")
MAX_AXIS_TILT_DEG = 5.0
"""A turntable axis tilted more than this from the base frame's vertical is refused (level the turntable)."""


@dataclass(frozen=True)
class DeviceSpec:
    """One configured device: its kind, driver name and the driver's validated config."""

    kind: Kind
    driver: str
    config: Any


@dataclass(frozen=True, eq=False)
class CellFile:
    """A parsed cell file.

    camera, arm, turntable: the configured devices (None when the section is absent).
    hand_eye: ``T_flange_camera``, the camera (OpenCV axes) in the arm's flange frame.
    arm_base: ``T_base_armbase``, the arm's base frame in the cell's base frame (plate centre, z up).
    turntable_axis: the plate's axis direction in the cell's base frame (unit, up; ``[devices.turntable_axis]
    direction``, written by ``nbv calibrate --write``); the axis passes through the base frame's origin (the
    calibration moves ``arm_base`` so that it does). A real cell places its frames with it
    (devices/hwcell.py, :func:`T_table_base`).
    allow_auto: whether auto mode may move these devices without a person approving each view.
    source: the file it was read from ("" when built from a dict).
    """

    camera: DeviceSpec | None = None
    arm: DeviceSpec | None = None
    turntable: DeviceSpec | None = None
    hand_eye: Pose = dataclasses.field(default_factory=Pose.identity)
    arm_base: Pose = dataclasses.field(default_factory=Pose.identity)
    turntable_axis: tuple[float, float, float] = (0.0, 0.0, 1.0)
    allow_auto: bool = False
    source: str = ""
    move_capture_hz: float | None = None
    """Capture during moves on this cell (``[devices] move_capture_hz``, frames per second, 0 = off); None: the
    server's ``devices.cell.move_capture_hz``."""

    def devices(self) -> list[DeviceSpec]:
        """The configured devices in the order camera, arm, turntable."""
        return [d for d in (self.camera, self.arm, self.turntable) if d is not None]

    def T_base_camera(self, T_armbase_flange: Pose) -> Pose:
        """The camera pose in the cell's base frame from the flange pose the arm's kinematics give
        (``T_base_armbase @ T_armbase_flange @ T_flange_camera``)."""
        return self.arm_base @ T_armbase_flange @ self.hand_eye

    def arm_mount(self) -> tuple[tuple[float, float, float], float]:
        """(position in metres, yaw in degrees) of the arm's mount: ``arm_base`` for a kinematic model that
        mounts the arm upright (rotated about the vertical only). ValueError if ``arm_base`` is tilted."""
        R = self.arm_base.rotation
        if abs(R[2, 2] - 1.0) > 1e-6:
            tilt = math.degrees(math.acos(max(-1.0, min(1.0, float(R[2, 2])))))
            raise ValueError(f"devices.arm_base: tilted {tilt:.2f} deg from upright; the arm model mounts it upright")
        x, y, z = (float(v) for v in self.arm_base.translation)
        return (x, y, z), math.degrees(math.atan2(R[1, 0], R[0, 0]))


def _coerce(cls: type, settings: dict[str, Any], prefix: str) -> dict[str, Any]:
    """``settings`` checked against the fields of dataclass ``cls``: unknown names, bool/number mixes."""
    fields = {f.name: f for f in dataclasses.fields(cls)}
    out: dict[str, Any] = {}
    for key, value in settings.items():
        if key not in fields:
            raise ValueError(f"{prefix}{key}: unknown setting (known: driver, {', '.join(sorted(fields))})")
        default = fields[key].default
        if isinstance(default, bool):
            if not isinstance(value, bool):
                raise ValueError(f"{prefix}{key}: expected true/false, got {value!r}")
        elif isinstance(default, int | float):
            if isinstance(value, bool) or not isinstance(value, int | float):
                raise ValueError(f"{prefix}{key}: expected a number, got {value!r}")
            if isinstance(default, float):
                value = float(value)
        elif isinstance(default, str) and not isinstance(value, str):
            raise ValueError(f"{prefix}{key}: expected a string, got {value!r}")
        out[key] = value
    return out


def _device(kind: Kind, section: Any, folder: Path) -> DeviceSpec:
    prefix = f"devices.{kind}."
    if not isinstance(section, dict):
        raise ValueError(f"devices.{kind}: expected a table, got {type(section).__name__}")
    settings = dict(section)
    name = settings.pop("driver", None)
    known = ", ".join(driver_names(kind))
    if not isinstance(name, str) or not name:
        raise ValueError(f"{prefix}driver: required (one of {known})")
    if (kind, name) not in REGISTRY:
        raise ValueError(f"{prefix}driver: unknown driver {name!r} (known: {known})")
    driver = REGISTRY[(kind, name)]
    settings = resolve_paths(driver, _coerce(driver.config_type, settings, prefix), folder)
    try:
        config = driver.config_type(**settings)
    except ValueError as exc:
        msg = str(exc)
        raise ValueError(msg if msg.startswith("devices.") else f"devices.{msg}") from None
    return DeviceSpec(kind, name, config)


def _numbers(value: Any, n: int, where: str, unit: str) -> list[float]:
    if not isinstance(value, list) or len(value) != n or not finite(*value):
        raise ValueError(f"{where}: must be {n} finite numbers ({unit}), got {value!r}")
    return [float(v) for v in value]


def _pose(name: str, section: Any) -> Pose:
    where = f"devices.{name}"
    if not isinstance(section, dict):
        raise ValueError(f"{where}: expected a table with translation and rotation_deg or quaternion_wxyz")
    unknown = set(section) - {"translation", "rotation_deg", "quaternion_wxyz"}
    if unknown:
        raise ValueError(
            f"{where}.{sorted(unknown)[0]}: unknown setting (known: translation, rotation_deg, quaternion_wxyz)"
        )
    t = _numbers(section.get("translation", [0.0, 0.0, 0.0]), 3, f"{where}.translation", "metres")
    if "rotation_deg" in section and "quaternion_wxyz" in section:
        raise ValueError(f"{where}: give rotation_deg or quaternion_wxyz, not both")
    if "quaternion_wxyz" in section:
        q = _numbers(section["quaternion_wxyz"], 4, f"{where}.quaternion_wxyz", "w, x, y, z")
        norm = math.sqrt(sum(v * v for v in q))
        if abs(norm - 1.0) > 1e-3:
            raise ValueError(f"{where}.quaternion_wxyz: must be a unit quaternion, norm is {norm:.4f}")
        return Pose.from_wxyz(np.array(q) / norm, t)
    rpy = _numbers(section.get("rotation_deg", [0.0, 0.0, 0.0]), 3, f"{where}.rotation_deg", "degrees")
    return Pose(Rotation.from_euler("xyz", rpy, degrees=True).as_matrix(), np.array(t))


def _axis(section: Any) -> tuple[float, float, float]:
    where = "devices.turntable_axis"
    if not isinstance(section, dict) or set(section) - {"direction"}:
        raise ValueError(f"{where}: expected a table with only direction = [x, y, z]")
    d = np.array(_numbers(section.get("direction", [0.0, 0.0, 1.0]), 3, f"{where}.direction", "a unit vector"))
    norm = float(np.linalg.norm(d))
    if norm < 1e-9:
        raise ValueError(f"{where}.direction: must not be zero")
    d /= norm
    tilt = math.degrees(math.acos(max(-1.0, min(1.0, float(d[2])))))
    if tilt > MAX_AXIS_TILT_DEG:
        raise ValueError(
            f"{where}.direction: tilted {tilt:.2f} deg from the vertical (at most {MAX_AXIS_TILT_DEG:g}); level the turntable"
        )
    return (float(d[0]), float(d[1]), float(d[2]))


def T_table_base(theta: float, axis: tuple[float, float, float] | NDArray[np.float64] = (0.0, 0.0, 1.0)) -> Pose:
    """The cell's base frame in the plate (table) frame with the plate at ``theta`` (rad): a rotation by ``-theta``
    about the axis (unit, through the origin); ``Rz(-theta)`` for a vertical axis. The table frame is the base
    frame at ``theta = 0``."""
    return Pose(Rotation.from_rotvec(-theta * np.asarray(axis, dtype=np.float64)).as_matrix(), np.zeros(3))


def parse_cell(data: dict[str, Any], folder: str | Path = ".", source: str = "") -> CellFile:
    """A CellFile from the parsed TOML (the whole document; only ``[devices]`` is read)."""
    devices = data.get("devices")
    if not isinstance(devices, dict):
        raise ValueError("devices: the cell file needs a [devices] table (with [devices.camera], ...)")
    for key in devices:
        if key not in TOP_KEYS:
            raise ValueError(f"devices.{key}: unknown setting (known: {', '.join(TOP_KEYS)})")
    allow_auto = devices.get("allow_auto", False)
    if not isinstance(allow_auto, bool):
        raise ValueError(f"devices.allow_auto: expected true/false, got {allow_auto!r}")
    hz = devices.get("move_capture_hz")
    if hz is not None and (isinstance(hz, bool) or not isinstance(hz, int | float) or not 0 <= hz <= 60):
        raise ValueError(f"devices.move_capture_hz: frames per second in [0, 60], got {hz!r}")
    folder = Path(folder)
    specs = {kind: _device(kind, devices[kind], folder) for kind in KINDS if kind in devices}
    poses = {name: _pose(name, devices[name]) for name in POSE_SECTIONS if name in devices}
    return CellFile(
        camera=specs.get("camera"),
        arm=specs.get("arm"),
        turntable=specs.get("turntable"),
        hand_eye=poses.get("hand_eye", Pose.identity()),
        arm_base=poses.get("arm_base", Pose.identity()),
        turntable_axis=_axis(devices["turntable_axis"]) if "turntable_axis" in devices else (0.0, 0.0, 1.0),
        allow_auto=allow_auto,
        source=source,
        move_capture_hz=None if hz is None else float(hz),
    )


def load_cell_file(path: str | Path) -> CellFile:
    """Read and validate a cell file. ValueError (one line, naming the file or the field) when it is bad."""
    path = Path(path)
    try:
        with open(path, "rb") as fh:
            data = tomllib.load(fh)
    except OSError as exc:
        raise ValueError(f"{path}: cannot read the cell file ({exc.strerror})") from None
    except tomllib.TOMLDecodeError as exc:
        raise ValueError(f"{path}: invalid TOML ({exc})") from None
    return parse_cell(data, path.parent, str(path))
