"""``nbv serve``: the workbench (uvicorn + viser in one process).

Used by ``nbv.cli`` as ``serve.add_arguments(parser)`` and ``serve.run(args) -> int``.
"""

from __future__ import annotations

import argparse
import dataclasses
import os
from pathlib import Path

from app.settings import AppSettings, check_exposure, load_settings, settings_from_dict
from devices.config import ARM_CHOICES_HELP, DeviceConfig, cell_with_arm
from nbv.flags import ConfigField, add_config_flags, flag_overrides
from nbv.options import arm_name, calibration_name, sensor_name
from planner.config import PlannerConfig

TOKEN_ENV = "NBV_TOKEN"
GRACE = 2
"""Seconds uvicorn lets running requests finish after SIGTERM before it cancels them."""


SERVE_ALIASES: dict[str, list[str]] = {
    "server.host": ["--host"],
    "server.port": ["--port"],
    "server.viser_port": ["--viser-port"],
    "server.models_dir": ["--models-dir"],
    "server.data_dir": ["--data-dir"],
    "server.token": ["--token"],
    "server.viser_public": ["--viser-public"],
    "server.cell": ["--cell"],
    "server.dry_run": ["--dry-run"],
    "devices.model": ["--model"],
    "devices.camera.sensor": ["--sensor"],
    "devices.camera.calibration": ["--calibration"],
    "devices.cell.move_capture_hz": ["--move-capture"],
}
"""The flags ``nbv serve`` had before every setting had its own: aliases of the generated ones."""


def _server_fields(parser: argparse.ArgumentParser) -> list[ConfigField]:
    """Flags of the ``[server]`` table, ``[planner]`` and ``[devices]`` (``[faults]``: the TOML file only)."""

    def server_only(f: ConfigField) -> bool:
        return f.path[1] in ("planner", "devices", "faults")

    fields = add_config_flags(
        parser, AppSettings, prefix=("server",), aliases=SERVE_ALIASES, exclude=server_only, title="server"
    )
    fields += add_config_flags(parser, PlannerConfig, prefix=("planner",))
    fields += add_config_flags(
        parser,
        DeviceConfig,
        prefix=("devices",),
        aliases=SERVE_ALIASES,
        types_={"devices.camera.sensor": sensor_name, "devices.camera.calibration": calibration_name},
    )
    return fields


def add_arguments(parser: argparse.ArgumentParser) -> None:
    """The options of ``nbv serve``: ``--config FILE`` and a flag per setting of its tables (``--server.port``,
    ``--planner.voxel.resolution``, ``--devices.camera.sensor``); flags override the file."""
    parser.add_argument("--config", type=Path, default=None, help="a TOML file with [server], [planner], [devices]")
    parser.add_argument(
        "--cors-origin",
        action="append",
        dest="server.cors_origins",
        default=None,
        metavar="ORIGIN",
        help="allow this origin (CORS): adds to --server.cors_origins; repeatable",
    )
    parser.add_argument("--log-level", default="info", choices=["critical", "error", "warning", "info", "debug"])
    parser.add_argument(
        "--arm",
        type=arm_name,
        default=None,
        help=f"the simulated cell's arm: {ARM_CHOICES_HELP} (default: [devices.cell.arm], else ur5; a session may "
        "pick another on the page)",
    )
    parser.set_defaults(config_fields=_server_fields(parser))


def settings_from_args(args: argparse.Namespace) -> AppSettings:
    """AppSettings from ``--config`` and the flags (flags win; the token also from $NBV_TOKEN).
    ValueError on bad values, and for a non-loopback host without a token."""
    settings = settings_from_flags(args)
    check_exposure(settings)
    check_cell(settings)
    return settings


def settings_from_flags(args: argparse.Namespace) -> AppSettings:
    """AppSettings from ``--config``, then the flags, then $NBV_TOKEN for a token not given (ValueError naming
    the setting for a bad value); nothing checked about where it would listen or the cell file."""
    settings = load_settings(args.config)
    data = flag_overrides(args, getattr(args, "config_fields", []))
    server = data.setdefault("server", {})
    if "token" not in server and os.environ.get(TOKEN_ENV):
        server["token"] = os.environ[TOKEN_ENV]
    if not server:
        del data["server"]
    if data:
        settings = settings_from_dict(data, settings)
    arm = getattr(args, "arm", None)
    if arm is not None:
        cell = cell_with_arm(settings.devices.cell, arm)
        settings = dataclasses.replace(settings, devices=dataclasses.replace(settings.devices, cell=cell))
    return settings


def check_cell(settings: AppSettings) -> None:
    """Read the cell file now, so a bad one stops the server at start-up (ValueError naming the field)."""
    if settings.dry_run and not settings.cell:
        raise ValueError("server.dry_run: needs a cell file (--cell or [server] cell)")
    if settings.cell:
        from devices.cellfile import load_cell_file

        load_cell_file(settings.cell)


def run(args: argparse.Namespace) -> int:
    """Serve until interrupted. Returns the exit code."""
    import uvicorn

    from app.main import create_app

    settings = settings_from_args(args)
    app = create_app(settings)
    query = "?token=..." if settings.token else ""
    print(f"nbv workbench: http://{settings.host}:{settings.port}/{query}  (3D viewer near port {settings.viser_port})")
    # SIGTERM: requests still running after GRACE seconds are cancelled, then the lifespan kills the sessions'
    # worker processes and closes the journals (each event was fsynced as it was written): down within 5 s
    uvicorn.run(app, host=settings.host, port=settings.port, log_level=args.log_level, timeout_graceful_shutdown=GRACE)
    return 0


def serve(args: argparse.Namespace) -> int:
    """Alias of :func:`run`."""
    return run(args)
