"""Driver names of the cell file -> the driver's config class and how to open the device.

``[devices.camera] driver = "realsense"`` picks ``REGISTRY[("camera", "realsense")]``: the remaining keys of
the section build its config class (one frozen dataclass per driver, fields documented there), and
``open(config)`` connects the device. Built in: cameras ``realsense``, ``sim``, ``replay``, ``ros2``; arms ``ur``,
``ros2``; turntables ``grbl``, ``modbus``, ``sim``, ``ros2``. Nothing here imports a vendor package.

:func:`override` swaps how a registered driver opens, for a ``with`` block: the tests run
``nbv devices check`` in-process on a production cell file (``driver = "ur"``) with the UR driver talking
to an in-process controller instead of ``ur_rtde``'s sockets; everything else (parsing, validation,
the driver's logic) is the production path.
"""

from __future__ import annotations

from collections.abc import Callable, Iterator
from contextlib import contextmanager
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Literal

from devices.config import CameraConfig
from devices.drivers.grbl import GrblConfig
from devices.drivers.modbus import ModbusTurntableConfig
from devices.drivers.realsense import RealSenseConfig
from devices.drivers.ros2 import Ros2ArmConfig, Ros2CameraConfig, Ros2TurntableConfig
from devices.drivers.ur import URConfig
from planner.validate import finite, integer, require

Kind = Literal["camera", "arm", "turntable"]
KINDS: tuple[Kind, ...] = ("camera", "arm", "turntable")


@dataclass(frozen=True)
class SimCameraConfig(CameraConfig):
    """``[devices.camera] driver = "sim"``: the simulated camera (every :class:`devices.config.CameraConfig`
    field) rendering an object, for rehearsing a scan without a camera."""

    model: str = "l-block"
    """A built-in object name or a mesh file (relative paths: from the cell file's folder)."""
    size: float = 0.2
    """The object is scaled so its largest extent is this, metres."""
    up: str = "y"
    """The mesh file's up axis, "y" or "z"."""
    plate_radius: float = 0.2
    """Radius of the rendered turntable plate, metres."""
    seed: int = 0
    """Seeds the depth noise."""

    def __post_init__(self) -> None:
        super().__post_init__()
        require(isinstance(self.model, str) and self.model.strip() != "", "camera.model: a name or a mesh path")
        require(finite(self.size) and self.size > 0, f"camera.size: must be > 0, got {self.size!r}")
        require(self.up in ("y", "z"), f"camera.up: 'y' or 'z', got {self.up!r}")
        require(finite(self.plate_radius) and self.plate_radius >= 0, "camera.plate_radius: must be >= 0")
        require(integer(self.seed) and self.seed >= 0, f"camera.seed: must be an integer >= 0, got {self.seed!r}")


@dataclass(frozen=True)
class ReplayCameraConfig:
    """``[devices.camera] driver = "replay"``: play back a recording folder (``docs/journal.md`` format)."""

    recording: str = ""
    """The recording folder (NAME.ply + NAME.json per view); relative paths: from the cell file's folder."""
    mode: str = "sequence"
    """"sequence" (frames in order) or "nearest" (the frame nearest the camera's pose)."""

    def __post_init__(self) -> None:
        require(isinstance(self.recording, str) and self.recording != "", "devices.camera.recording: required")
        require(
            self.mode in ("sequence", "nearest"), f"devices.camera.mode: 'sequence' or 'nearest', got {self.mode!r}"
        )


@dataclass(frozen=True)
class SimTurntableConfig:
    """``[devices.turntable] driver = "sim"``: a turntable that turns instantly (rehearsal)."""

    angle_deg: float = 0.0
    """Starting plate angle, degrees."""

    def __post_init__(self) -> None:
        require(finite(self.angle_deg), f"devices.turntable.angle_deg: must be finite, got {self.angle_deg!r}")


def _open_realsense(config: RealSenseConfig) -> Any:
    from devices.drivers.realsense import RealSenseCamera

    return RealSenseCamera(config)


def _open_sim_camera(config: SimCameraConfig) -> Any:
    from devices.builtins import resolve_model
    from devices.sim import SimulatedCamera

    _, mesh = resolve_model(config.model, up=config.up, size=config.size)  # type: ignore[arg-type]
    return SimulatedCamera(mesh, config, plate_radius=config.plate_radius, seed=config.seed)


def _open_replay(config: ReplayCameraConfig) -> Any:
    from devices.replay import ReplayCamera, load_recording

    return ReplayCamera(load_recording(config.recording), config.mode)  # type: ignore[arg-type]


def _open_ur(config: URConfig) -> Any:
    from devices.drivers.ur import URArm

    return URArm(config)


def _open_grbl(config: GrblConfig) -> Any:
    from devices.drivers.grbl import GrblTurntable

    return GrblTurntable(config)


def _open_modbus(config: ModbusTurntableConfig) -> Any:
    from devices.drivers.modbus import ModbusTurntable

    return ModbusTurntable(config)


def _open_sim_turntable(config: SimTurntableConfig) -> Any:
    import math

    from devices.sim import SimulatedTurntable

    return SimulatedTurntable(math.radians(config.angle_deg))


def _open_ros2_camera(config: Ros2CameraConfig) -> Any:
    from devices.drivers.ros2.camera import Ros2Camera

    return Ros2Camera(config)


def _open_ros2_arm(config: Ros2ArmConfig) -> Any:
    from devices.drivers.ros2.arm import Ros2Arm

    return Ros2Arm(config)


def _open_ros2_turntable(config: Ros2TurntableConfig) -> Any:
    from devices.drivers.ros2.turntable import Ros2Turntable

    return Ros2Turntable(config)


@dataclass(frozen=True)
class Driver:
    """One driver of the cell file: its config class, which of its fields are file paths, how to open it."""

    config_type: type
    open: Callable[[Any], Any]
    path_fields: tuple[str, ...] = field(default=())


REGISTRY: dict[tuple[Kind, str], Driver] = {
    ("camera", "realsense"): Driver(RealSenseConfig, _open_realsense, ("playback",)),
    ("camera", "sim"): Driver(SimCameraConfig, _open_sim_camera, ("model",)),
    ("camera", "replay"): Driver(ReplayCameraConfig, _open_replay, ("recording",)),
    ("arm", "ur"): Driver(URConfig, _open_ur),
    ("turntable", "grbl"): Driver(GrblConfig, _open_grbl),
    ("turntable", "modbus"): Driver(ModbusTurntableConfig, _open_modbus),
    ("turntable", "sim"): Driver(SimTurntableConfig, _open_sim_turntable),
    ("camera", "ros2"): Driver(Ros2CameraConfig, _open_ros2_camera),
    ("arm", "ros2"): Driver(Ros2ArmConfig, _open_ros2_arm),
    ("turntable", "ros2"): Driver(Ros2TurntableConfig, _open_ros2_turntable),
}


def driver_names(kind: Kind) -> list[str]:
    """The registered driver names of one kind, sorted."""
    return sorted(name for k, name in REGISTRY if k == kind)


def register(kind: Kind, name: str, driver: Driver) -> None:
    """Add (or replace) a driver: how a lab plugs in its own device without touching this package."""
    require(kind in KINDS, f"kind: one of {', '.join(KINDS)}, got {kind!r}")
    require(isinstance(name, str) and name.strip() != "", "name: a driver name")
    REGISTRY[(kind, name)] = driver


@contextmanager
def override(kind: Kind, name: str, open_device: Callable[[Any], Any]) -> Iterator[None]:
    """Within the block, ``driver = name`` devices of ``kind`` open with ``open_device(config)`` (same config
    class and parsing); the registered opener is restored afterwards."""
    before = REGISTRY[(kind, name)]
    REGISTRY[(kind, name)] = Driver(before.config_type, open_device, before.path_fields)
    try:
        yield
    finally:
        REGISTRY[(kind, name)] = before


def resolve_paths(driver: Driver, settings: dict[str, Any], folder: Path) -> dict[str, Any]:
    """``settings`` with the driver's relative file paths made relative to ``folder`` (the cell file's)."""
    out = dict(settings)
    for name in driver.path_fields:
        value = out.get(name)
        if isinstance(value, str) and value and not Path(value).is_absolute():
            candidate = folder / value
            if name != "model" or candidate.exists():  # a model may be a built-in name, not a path
                out[name] = str(candidate)
    return out
