"""Settings of the workbench server: where it listens, where models live, the default session.

``AppSettings`` is frozen; build it with :func:`load_settings` from a TOML file
(``nbv serve --config FILE``) plus command-line overrides. The TOML layout is::

    [server]
    host = "127.0.0.1"
    port = 8000
    viser_port = 8080
    models_dir = "../shared/models"

    [planner]            # any subset of planner.config.PlannerConfig
    voxel = { resolution = 0.01 }

    [devices]            # any subset of devices.config.DeviceConfig
    model = "l-block"    # the default model of a new session
    camera = { depth_noise_std = 0.0005 }
"""

from __future__ import annotations

import dataclasses
import tomllib
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from devices.config import DeviceConfig
from planner.config import PlannerConfig, merge


def default_models_dir() -> Path:
    """``../shared/models`` when it exists (the team's test meshes), else ``./models``."""
    shared = Path("../shared/models")
    return shared if shared.is_dir() else Path("models")


@dataclass(frozen=True)
class AppSettings:
    """Everything the server needs at start-up. Paths are resolved when used, not here."""

    host: str = "127.0.0.1"
    """Interface uvicorn binds (127.0.0.1 unless you mean to expose the workbench)."""
    port: int = 8000
    """HTTP port of the page and the REST API."""
    viser_host: str = "127.0.0.1"
    """Interface the viser server binds. Follows ``host`` when built by ``load_settings``."""
    viser_port: int = 8080
    """Preferred viser port; viser moves to the next free one when it is taken (0 = any free port)."""
    models_dir: Path = field(default_factory=default_models_dir)
    """Directory of mesh files offered as models (.obj, .ply, .stl, .off, .glb)."""
    data_dir: Path = Path("nbv-data")
    """Where uploads (and, later, session journals) are stored."""
    max_upload_bytes: int = 50 * 1024 * 1024
    """Uploads larger than this are refused (413)."""
    planner: PlannerConfig = field(default_factory=PlannerConfig)
    """Default planner configuration; a session's ``config`` overrides any subset of it."""
    devices: DeviceConfig = field(default_factory=DeviceConfig)
    """The simulated devices. ``devices.model`` is the default model (a built-in name or a file
    in models_dir), ``devices.size`` / ``devices.up`` apply to every model file."""
    scene: bool = True
    """Start the viser server (tests of the REST API alone may turn it off)."""
    viser_verbose: bool = False
    """Let viser print its banner."""

    def __post_init__(self) -> None:
        for name in ("port", "viser_port"):
            value = getattr(self, name)
            if not isinstance(value, int) or not 0 <= value <= 65535:
                raise ValueError(f"server.{name}: must be an integer in [0, 65535], got {value!r}")
        if not isinstance(self.max_upload_bytes, int) or self.max_upload_bytes < 1:
            raise ValueError(f"server.max_upload_bytes: must be a positive integer, got {self.max_upload_bytes!r}")
        object.__setattr__(self, "models_dir", Path(self.models_dir))
        object.__setattr__(self, "data_dir", Path(self.data_dir))

    def replace(self, **changes: Any) -> AppSettings:
        """A copy with some fields changed."""
        return dataclasses.replace(self, **changes)


_SERVER_KEYS = {f.name for f in dataclasses.fields(AppSettings)} - {"planner", "devices"}


def settings_from_dict(data: dict[str, Any], base: AppSettings | None = None) -> AppSettings:
    """Settings from a nested dict with ``server``, ``planner`` and ``devices`` tables (all optional)."""
    base = base or AppSettings()
    unknown = set(data) - {"server", "planner", "devices"}
    if unknown:
        raise ValueError(f"settings: unknown table(s) {sorted(unknown)} (known: server, planner, devices)")
    server = dict(data.get("server", {}))
    bad = set(server) - _SERVER_KEYS
    if bad:
        raise ValueError(f"server: unknown setting(s) {sorted(bad)} (known: {', '.join(sorted(_SERVER_KEYS))})")
    if "host" in server and "viser_host" not in server:
        server["viser_host"] = server["host"]
    planner = base.planner.replace(**data["planner"]) if "planner" in data else base.planner
    devices = merge(base.devices, data["devices"], "devices.") if "devices" in data else base.devices
    return base.replace(**server, planner=planner, devices=devices)


def load_settings(path: str | Path | None = None, model: str | None = None, **overrides: Any) -> AppSettings:
    """Settings from an optional TOML file, then keyword overrides of the ``server`` table and the
    default ``model`` (``None`` values are ignored)."""
    data: dict[str, Any] = {}
    if path is not None:
        try:
            with open(path, "rb") as fh:
                data = tomllib.load(fh)
        except tomllib.TOMLDecodeError as exc:
            raise ValueError(f"{path}: invalid TOML ({exc})") from None
        except OSError as exc:
            raise ValueError(f"{path}: cannot read ({exc.strerror})") from None
    settings = settings_from_dict(data)
    given = {k: v for k, v in overrides.items() if v is not None}
    if given:
        settings = settings_from_dict({"server": given}, settings)
    if model is not None:
        settings = settings.replace(devices=dataclasses.replace(settings.devices, model=model))
    return settings
