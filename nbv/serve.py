"""``nbv serve``: the workbench (uvicorn + viser in one process).

Used by ``nbv.cli`` as ``serve.add_arguments(parser)`` and ``serve.run(args) -> int``.
"""

from __future__ import annotations

import argparse
import dataclasses
import os
from pathlib import Path

from app.settings import AppSettings, check_exposure, load_settings
from devices.calibration_error import CALIBRATIONS
from devices.sensors.presets import SENSORS
from nbv.options import calibration_name, sensor_name

TOKEN_ENV = "NBV_TOKEN"
GRACE = 2
"""Seconds uvicorn lets running requests finish after SIGTERM before it cancels them."""


def add_arguments(parser: argparse.ArgumentParser) -> None:
    """The options of ``nbv serve`` (flags override the ``[server]`` table of ``--config``)."""
    parser.add_argument("--host", default=None, help="interface to bind (default 127.0.0.1)")
    parser.add_argument("--port", type=int, default=None, help="HTTP port of the page and the API (default 8000)")
    parser.add_argument(
        "--viser-port",
        type=int,
        default=None,
        help="preferred port of the 3D viewer; the next free one is used if busy",
    )
    parser.add_argument("--model", default=None, help="default object of a new session (default l-block)")
    parser.add_argument("--models-dir", type=Path, default=None, help="directory of mesh files offered as models")
    parser.add_argument(
        "--sensor",
        type=sensor_name,
        default=None,
        help=f"default depth sensor of new simulated sessions: {', '.join(SENSORS)} (default ideal, or the config's)",
    )
    parser.add_argument(
        "--calibration",
        type=calibration_name,
        default=None,
        help=f"default calibration error of new simulated sessions: {', '.join(CALIBRATIONS)} (default none)",
    )
    parser.add_argument(
        "--data-dir", type=Path, default=None, help="where uploads, session journals and recordings go (./nbv-data)"
    )
    parser.add_argument(
        "--token",
        default=None,
        help=f"API token, required to bind a non-loopback host (default: ${TOKEN_ENV}); see docs/security.md",
    )
    parser.add_argument(
        "--cors-origin", action="append", default=None, metavar="ORIGIN", help="allow this origin (CORS); repeatable"
    )
    parser.add_argument(
        "--viser-public",
        action="store_true",
        default=None,
        help="with a token on an exposed host, bind the 3D viewer there too (it has no authentication)",
    )
    parser.add_argument("--config", type=Path, default=None, help="a TOML file with [server], [planner], [devices]")
    parser.add_argument(
        "--cell",
        type=Path,
        default=None,
        help="a cell file (docs/hardware.md): new sessions drive its camera, arm and turntable",
    )
    parser.add_argument(
        "--dry-run",
        action="store_true",
        default=None,
        help="with --cell: plan, preview and approve as usual, but capture from the simulator and move no device",
    )
    parser.add_argument("--log-level", default="info", choices=["critical", "error", "warning", "info", "debug"])


def settings_from_args(args: argparse.Namespace) -> AppSettings:
    """AppSettings from ``--config`` and the flags (flags win; the token also from $NBV_TOKEN).
    ValueError on bad values, and for a non-loopback host without a token."""
    settings = load_settings(
        args.config,
        model=args.model,
        host=args.host,
        port=args.port,
        viser_port=args.viser_port,
        models_dir=args.models_dir,
        data_dir=args.data_dir,
        token=getattr(args, "token", None) or os.environ.get(TOKEN_ENV) or None,
        cors_origins=tuple(args.cors_origin) if getattr(args, "cors_origin", None) else None,
        viser_public=getattr(args, "viser_public", None),
        cell=str(args.cell) if getattr(args, "cell", None) else None,
        dry_run=getattr(args, "dry_run", None),
    )
    camera = {k: v for k in ("sensor", "calibration") if (v := getattr(args, k, None)) is not None}
    if camera:  # the default of new simulated sessions (a hardware session never takes it)
        devices = settings.devices
        settings = settings.replace(
            devices=dataclasses.replace(devices, camera=dataclasses.replace(devices.camera, **camera))
        )
    check_exposure(settings)
    check_cell(settings)
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
