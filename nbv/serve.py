"""``nbv serve``: the workbench (uvicorn + viser in one process).

Used by ``nbv.cli`` as ``serve.add_arguments(parser)`` and ``serve.run(args) -> int``.
"""

from __future__ import annotations

import argparse
from pathlib import Path

from app.settings import AppSettings, load_settings


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
    parser.add_argument("--data-dir", type=Path, default=None, help="where uploads and session data go (./nbv-data)")
    parser.add_argument("--config", type=Path, default=None, help="a TOML file with [server], [planner], [devices]")
    parser.add_argument("--log-level", default="info", choices=["critical", "error", "warning", "info", "debug"])


def settings_from_args(args: argparse.Namespace) -> AppSettings:
    """AppSettings from ``--config`` and the flags (flags win). ValueError on bad values."""
    return load_settings(
        args.config,
        model=args.model,
        host=args.host,
        port=args.port,
        viser_port=args.viser_port,
        models_dir=args.models_dir,
        data_dir=args.data_dir,
    )


def run(args: argparse.Namespace) -> int:
    """Serve until interrupted. Returns the exit code."""
    import uvicorn

    from app.main import create_app

    settings = settings_from_args(args)
    app = create_app(settings)
    print(f"nbv workbench: http://{settings.host}:{settings.port}/  (3D viewer near port {settings.viser_port})")
    uvicorn.run(app, host=settings.host, port=settings.port, log_level=args.log_level)
    return 0


def serve(args: argparse.Namespace) -> int:
    """Alias of :func:`run`."""
    return run(args)
