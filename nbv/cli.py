"""The ``nbv`` command: scan, profile, serve, ... (one-line errors, never a traceback)."""

from __future__ import annotations

import argparse
import json
import sys
from collections.abc import Sequence
from pathlib import Path
from typing import Any

from planner.config import PlannerConfig

EXIT_BAD_INPUT = 2


class CliError(Exception):
    """A user-facing error: printed as one line, exit code 2."""


# ---------------------------------------------------------------- shared options


def add_scan_options(p: argparse.ArgumentParser, *, model_required: bool = True) -> None:
    """Options shared by scan, profile and bench (names match the config fields)."""
    if model_required:
        p.add_argument("--model", required=True, help="a built-in object name or a mesh file (PLY/OBJ/STL/OFF/GLB)")
    p.add_argument("--views", type=int, default=None, help="maximum views (termination.max_views, default 10)")
    p.add_argument("--resolution", type=float, default=None, help="voxel size in metres (default 0.01)")
    p.add_argument("--candidates", type=int, default=None, help="N, candidate views (default 400)")
    p.add_argument("--parallels", type=int, default=None, help="alpha, parallels on the hemisphere (default 10)")
    p.add_argument("--partitions", type=int, default=None, help="beta, longitude sectors (default 4)")
    p.add_argument("--t-min", type=int, default=None, help="fewest GMM components (default 5)")
    p.add_argument("--t-max", type=int, default=None, help="most GMM components (default 50)")
    p.add_argument("--gamma", type=float, default=None, help="frontier sphere radius for B's growth, m (default 0.02)")
    p.add_argument("--working-distance", type=float, default=None, help="d_c, camera working distance, m")
    p.add_argument("--search", choices=["fast", "exhaustive"], default=None, help="BIC model selection search")
    p.add_argument("--growth-threshold", type=float, default=None, help="stop when point growth < this (0: off)")
    p.add_argument("--size", type=float, default=0.2, help="largest extent of the object, m (default 0.2)")
    p.add_argument("--up", choices=["y", "z"], default="y", help="the mesh file's up axis (default y)")
    p.add_argument(
        "--yaw", type=float, default=0.0, help="turn the object about the turntable axis before scanning, degrees"
    )
    p.add_argument("--seed", type=int, default=0, help="seed of every random choice (default 0)")
    p.add_argument("--depth-noise", type=float, default=0.0, help="std of Gaussian depth noise, m (default 0)")
    p.add_argument("--pose-noise", type=float, default=0.0, help="std of reported-pose translation noise, m")
    p.add_argument("--config", type=Path, default=None, help="a TOML file with planner settings")


def planner_config_from_args(args: argparse.Namespace) -> PlannerConfig:
    """PlannerConfig from --config and the flags (flags win). ValueError on bad values."""
    config = PlannerConfig.from_toml(args.config) if getattr(args, "config", None) else PlannerConfig()
    overrides: dict[str, dict[str, Any]] = {}

    def put(section: str, key: str, value: Any) -> None:
        if value is not None:
            overrides.setdefault(section, {})[key] = value

    put("termination", "max_views", args.views)
    put("termination", "growth_threshold", args.growth_threshold)
    put("voxel", "resolution", args.resolution)
    put("voxel", "gamma", args.gamma)
    put("candidates", "count", args.candidates)
    put("candidates", "parallels", args.parallels)
    put("candidates", "working_distance", args.working_distance)
    put("partitions", "sectors", args.partitions)
    put("cluster", "t_min", args.t_min)
    put("cluster", "t_max", args.t_max)
    put("cluster", "search", args.search)
    put("cluster", "seed", args.seed)
    return config.replace(**overrides)


# ---------------------------------------------------------------- commands


def cmd_scan(args: argparse.Namespace) -> int:
    from nbv.run import run_and_report

    run_and_report(args, profile=False)
    return 0


def cmd_profile(args: argparse.Namespace) -> int:
    from nbv.run import run_and_report

    run_and_report(args, profile=True)
    return 0


def cmd_models(args: argparse.Namespace) -> int:
    from devices.builtins import BUILTIN_OBJECTS

    for name, text in BUILTIN_OBJECTS.items():
        print(f"{name:12s} {text}")
    return 0


def cmd_config(args: argparse.Namespace) -> int:
    print(json.dumps(PlannerConfig().to_dict(), indent=2))
    return 0


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(prog="nbv", description="Projection-based next-best-view planning workbench")
    sub = parser.add_subparsers(dest="command", required=True)

    p = sub.add_parser("scan", help="scan a mesh in the simulated cell (Algorithm 1, headless)")
    add_scan_options(p)
    p.add_argument("--planner", default="projection", help="view evaluator (default projection)")
    p.add_argument("--out", type=Path, default=Path("out/scan"), help="output directory (metrics.json, cloud.ply)")
    p.add_argument("--no-reachable", action="store_true", help="skip the reachable-coverage ceiling")
    p.set_defaults(func=cmd_scan)

    p = sub.add_parser("profile", help="scan and print a stage-by-stage timing table")
    add_scan_options(p)
    p.add_argument("--planner", default="projection", help=argparse.SUPPRESS)
    p.add_argument("--out", type=Path, default=Path("out/profile"), help="output directory (profile.json)")
    p.add_argument("--fidelity", action="store_true", help="check BIC fidelity against the exhaustive sweep")
    p.add_argument("--fidelity-iterations", default="1,5,10", help="iterations checked with --fidelity")
    p.add_argument("--no-reachable", action="store_true", help=argparse.SUPPRESS)
    p.set_defaults(func=cmd_profile)

    p = sub.add_parser("models", help="list the built-in objects")
    p.set_defaults(func=cmd_models)

    p = sub.add_parser("config", help="print the default planner configuration")
    p.set_defaults(func=cmd_config)

    try:
        from nbv import serve
    except ImportError:  # pragma: no cover - the app is optional at import time
        serve = None  # type: ignore[assignment]
    if serve is not None and hasattr(serve, "add_arguments"):
        p = sub.add_parser("serve", help="serve the workbench (FastAPI + viser)")
        serve.add_arguments(p)
        p.set_defaults(func=serve.run)

    for name in ("bench", "replay"):
        try:
            module = __import__(f"nbv.{name}", fromlist=["add_arguments", "run"])
        except ImportError:
            continue
        p = sub.add_parser(name, help=(module.__doc__ or "").strip().splitlines()[0] if module.__doc__ else None)
        module.add_arguments(p)
        p.set_defaults(func=module.run)
    return parser


def main(argv: Sequence[str] | None = None) -> int:
    parser = build_parser()
    args = parser.parse_args(argv)
    try:
        return int(args.func(args) or 0)
    except KeyboardInterrupt:
        print("nbv: interrupted", file=sys.stderr)
        return 130
    except (CliError, ValueError, OSError) as exc:
        print(f"nbv: error: {exc}", file=sys.stderr)
        return EXIT_BAD_INPUT
    except Exception as exc:  # device faults and the like: still one line
        from devices.protocols import DeviceError

        if isinstance(exc, DeviceError):
            print(f"nbv: device error: {exc}", file=sys.stderr)
            return 3
        raise


if __name__ == "__main__":  # pragma: no cover
    sys.exit(main())
