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
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from devices.faults import FaultConfig
from planner.config import merge
from planner.validate import integer
from workbench import WorkbenchSettings

MIN_TOKEN_LENGTH = 12


@dataclass(frozen=True)
class AppSettings(WorkbenchSettings):
    """Everything the server needs at start-up: the sessions' settings (:class:`WorkbenchSettings`: models_dir,
    data_dir, max_upload_bytes, capture_timeout, move_timeout, journal, faults, planner, devices) and where
    and how the server listens."""

    host: str = "127.0.0.1"
    """Interface uvicorn binds (127.0.0.1 unless you mean to expose the workbench)."""
    port: int = 8000
    """HTTP port of the page and the REST API."""
    viser_host: str = "127.0.0.1"
    """Interface the viser server binds. Follows ``host`` when built by ``load_settings``."""
    viser_port: int = 8080
    """Preferred viser port; viser moves to the next free one when it is taken (0 = any free port)."""
    max_body_bytes: int = 1024 * 1024
    """Any request body other than an upload larger than this is refused (413) before it is read."""
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
    fault_api: bool = False
    """Test flag: allow fault injection over the API (``faults`` in ``POST /api/sessions`` and the route
    ``POST /api/sessions/{id}/faults`` that injects a fault now). Off: both are refused (422 / 404)."""
    scene: bool = True
    """Start the viser server (tests of the REST API alone may turn it off)."""
    viser_verbose: bool = False
    """Let viser print its banner."""

    def __post_init__(self) -> None:
        super().__post_init__()
        for name in ("port", "viser_port"):
            value = getattr(self, name)
            if not isinstance(value, int) or not 0 <= value <= 65535:
                raise ValueError(f"server.{name}: must be an integer in [0, 65535], got {value!r}")
        if not integer(self.max_body_bytes) or self.max_body_bytes < 1:
            raise ValueError(f"server.max_body_bytes: must be a positive integer, got {self.max_body_bytes!r}")
        if self.token is not None and (not isinstance(self.token, str) or len(self.token) < MIN_TOKEN_LENGTH):
            raise ValueError(f"server.token: must be a string of at least {MIN_TOKEN_LENGTH} characters")
        for name in ("cors_origins", "allowed_hosts"):
            value = getattr(self, name)
            if isinstance(value, str) or not all(isinstance(o, str) for o in value):
                raise ValueError(f"server.{name}: must be a list of strings, got {value!r}")
        object.__setattr__(self, "allowed_hosts", tuple(h.lower() for h in self.allowed_hosts))
        object.__setattr__(self, "cors_origins", tuple(o.rstrip("/") for o in self.cors_origins))

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


def viewer_host(settings: AppSettings) -> str:
    """Where viser listens: ``viser_host``, but 127.0.0.1 when the API is exposed (viser has no authentication)
    unless ``viser_public`` says otherwise."""
    if is_loopback(settings.host) or settings.viser_public:
        return settings.viser_host
    return "127.0.0.1"


def check_exposure(settings: AppSettings) -> None:
    """Refuse (ValueError) to serve a non-loopback host without a token: anyone reaching the port could
    move the robot."""
    if not is_loopback(settings.host) and not settings.token:
        raise ValueError(
            f"refusing to listen on {settings.host}: any machine that reaches it could drive the robot. "
            "Set a token (--token or the NBV_TOKEN environment variable) or bind 127.0.0.1"
        )
    if settings.scene and not is_loopback(viewer_host(settings)) and not settings.token:
        raise ValueError(
            f"refusing to serve the 3D viewer on {viewer_host(settings)} without a token: its tickets come from "
            "the REST API, which needs one off loopback. Set a token or viser_host = 127.0.0.1"
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
    if isinstance(server.get("mesh_limits"), dict):  # any subset of its fields, the others kept
        server["mesh_limits"] = merge(base.mesh_limits, server["mesh_limits"], "server.mesh_limits.")
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
