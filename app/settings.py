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

    [faults]             # devices.faults.FaultConfig: injected into every session's devices
    schedule = [{ kind = "capture_failure", at = 3 }]

Exposure: the server refuses to start on a non-loopback ``host`` without a
``token`` (:func:`check_exposure`); see ``docs/security.md``.
"""

from __future__ import annotations

import dataclasses
import ipaddress
import tomllib
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from devices.config import DeviceConfig
from devices.faults import FaultConfig
from planner.config import PlannerConfig, merge
from planner.validate import finite, integer

MIN_TOKEN_LENGTH = 12


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
    """Where uploads (``uploads/``), session journals (``sessions/``) and replay recordings
    (``recordings/``) live. See docs/journal.md."""
    max_upload_bytes: int = 50 * 1024 * 1024
    """Uploads larger than this are refused (413)."""
    max_body_bytes: int = 1024 * 1024
    """Any other request body larger than this is refused (413) before it is read."""
    token: str | None = None
    """When set, every ``/api`` request must carry it (``Authorization: Bearer`` or ``?token=``).
    Required to bind a non-loopback host."""
    cors_origins: tuple[str, ...] = ()
    """Origins allowed to call the API from another page (CORS). Empty: closed."""
    allowed_hosts: tuple[str, ...] = ()
    """Extra ``Host`` names a loopback-bound server answers to (e.g. the name a local TLS proxy forwards);
    127.0.0.1, localhost and ::1 always work."""
    viser_public: bool = False
    """Bind the 3D viewer to ``viser_host`` even when the API is exposed with a token (viser has no
    authentication; by default it then listens on 127.0.0.1 only)."""
    capture_timeout: float = 30.0
    """A capture that takes longer fails with a timeout (the session goes to state error), seconds."""
    move_timeout: float = 120.0
    """A cell move (turntable + arm) that takes longer fails with a timeout, seconds."""
    journal: bool = True
    """Journal every session under ``data_dir/sessions`` (resume after a crash, ``nbv replay``)."""
    faults: FaultConfig = field(default_factory=FaultConfig)
    """Faults injected into every new session's devices (a session's own ``faults`` replace these)."""
    fault_api: bool = False
    """Enable the test-only route ``POST /api/sessions/{id}/faults`` that injects a fault now."""
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
        for name in ("max_upload_bytes", "max_body_bytes"):
            value = getattr(self, name)
            if not integer(value) or value < 1:
                raise ValueError(f"server.{name}: must be a positive integer, got {value!r}")
        for name in ("capture_timeout", "move_timeout"):
            value = getattr(self, name)
            if not finite(value):
                raise ValueError(f"server.{name}: must be a number of seconds (0: no limit), got {value!r}")
            if value < 0:
                raise ValueError(f"server.{name}: must be >= 0 (0: no limit), got {value!r}")
        if self.token is not None and (not isinstance(self.token, str) or len(self.token) < MIN_TOKEN_LENGTH):
            raise ValueError(f"server.token: must be a string of at least {MIN_TOKEN_LENGTH} characters")
        for name in ("cors_origins", "allowed_hosts"):
            value = getattr(self, name)
            if isinstance(value, str) or not all(isinstance(o, str) for o in value):
                raise ValueError(f"server.{name}: must be a list of strings, got {value!r}")
        object.__setattr__(self, "allowed_hosts", tuple(h.lower() for h in self.allowed_hosts))
        if not isinstance(self.faults, FaultConfig):
            raise ValueError("faults: must be a FaultConfig")
        object.__setattr__(self, "cors_origins", tuple(o.rstrip("/") for o in self.cors_origins))
        object.__setattr__(self, "models_dir", Path(self.models_dir))
        object.__setattr__(self, "data_dir", Path(self.data_dir))

    def replace(self, **changes: Any) -> AppSettings:
        """A copy with some fields changed."""
        return dataclasses.replace(self, **changes)


def is_loopback(host: str) -> bool:
    """``host`` names only this machine (127.0.0.0/8, ::1, localhost)."""
    if host.strip("[]").lower() == "localhost":
        return True
    try:
        return ipaddress.ip_address(host.strip("[]")).is_loopback
    except ValueError:
        return False


def check_exposure(settings: AppSettings) -> None:
    """Refuse (ValueError) to serve a non-loopback host without a token: anyone reaching the port could
    move the robot."""
    if not is_loopback(settings.host) and not settings.token:
        raise ValueError(
            f"refusing to listen on {settings.host}: any machine that reaches it could drive the robot. "
            "Set a token (--token or the NBV_TOKEN environment variable) or bind 127.0.0.1"
        )


_TABLES = {"server", "planner", "devices", "faults"}
_SERVER_KEYS = {f.name for f in dataclasses.fields(AppSettings)} - {"planner", "devices", "faults"}


def settings_from_dict(data: dict[str, Any], base: AppSettings | None = None) -> AppSettings:
    """Settings from a nested dict with ``server``, ``planner``, ``devices`` and ``faults`` tables (all optional)."""
    base = base or AppSettings()
    unknown = set(data) - _TABLES
    if unknown:
        raise ValueError(f"settings: unknown table(s) {sorted(unknown)} (known: {', '.join(sorted(_TABLES))})")
    server = dict(data.get("server", {}))
    bad = set(server) - _SERVER_KEYS
    if bad:
        raise ValueError(f"server: unknown setting(s) {sorted(bad)} (known: {', '.join(sorted(_SERVER_KEYS))})")
    if "host" in server and "viser_host" not in server:
        server["viser_host"] = server["host"]
    planner = base.planner.replace(**data["planner"]) if "planner" in data else base.planner
    devices = merge(base.devices, data["devices"], "devices.") if "devices" in data else base.devices
    faults = FaultConfig.from_dict(data["faults"]) if "faults" in data else base.faults
    for key in ("cors_origins", "allowed_hosts"):
        if isinstance(server.get(key), list):
            server[key] = tuple(server[key])
    return base.replace(**server, planner=planner, devices=devices, faults=faults)


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
