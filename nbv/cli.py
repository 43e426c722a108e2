"""The ``nbv`` command: scan, profile, serve, ... (one-line errors, never a traceback)."""

from __future__ import annotations

import argparse
import json
import sys
from collections.abc import Sequence
from pathlib import Path

from nbv import arms_cmd, calibrate_cmd, devices_cmd
from nbv.options import EXIT_BAD_INPUT, CliError, add_scan_options
from planner.config import PlannerConfig

SCAN_USAGE = "nbv {} --model MODEL [--config FILE] [--SECTION.KEY VALUE ...] [options]"
"""The usage line of scan, profile and bench (their help lists every planner setting's flag)."""

# ---------------------------------------------------------------- commands


def cmd_scan(args: argparse.Namespace) -> int:
    from nbv.scan_cmd import run_and_report

    if args.recorded is not None:
        from nbv.bench_recorded import scan_recorded

        scan_recorded(args)
        return 0
    run_and_report(args, profile=False)
    return 0


def cmd_profile(args: argparse.Namespace) -> int:
    from nbv.scan_cmd import run_and_report

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

    p = sub.add_parser(
        "scan",
        help="scan a mesh in the simulated cell (Algorithm 1, headless)",
        usage=SCAN_USAGE.format("scan"),
        allow_abbrev=False,
    )
    add_scan_options(p, recorded=True)
    p.add_argument("--planner", default="projection", help="view evaluator (default %(default)s)")
    p.add_argument(
        "--out", type=Path, default=Path("out/scan"), help="output directory (metrics.json, cloud.ply, surface.ply)"
    )
    p.add_argument("--no-reachable", action="store_true", help="skip the reachable-coverage ceiling")
    p.set_defaults(func=cmd_scan)

    p = sub.add_parser(
        "profile",
        help="scan and print a stage-by-stage timing table",
        usage=SCAN_USAGE.format("profile"),
        allow_abbrev=False,
    )
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
        p = sub.add_parser(
            "serve",
            help="serve the workbench (FastAPI + viser)",
            usage="nbv serve [--config FILE] [--SECTION.KEY VALUE ...]",
            allow_abbrev=False,
        )
        serve.add_arguments(p)
        p.set_defaults(func=serve.run)

    p = sub.add_parser("arms", help="the arm presets; nbv arms check NAME: where to mount it, what it reaches")
    arms_cmd.add_arguments(p)
    p.set_defaults(func=arms_cmd.run)

    p = sub.add_parser("devices", help="real hardware: nbv devices check --config cell.toml")
    devices_cmd.add_arguments(p)
    p.set_defaults(func=devices_cmd.run)

    p = sub.add_parser("calibrate", help="commission a cell: hand-eye transform and turntable axis from a target")
    calibrate_cmd.add_arguments(p)
    p.set_defaults(func=calibrate_cmd.run)

    for name in ("bench", "replay", "record", "export-bag"):
        try:
            module = __import__(f"nbv.{name.replace('-', '_')}", fromlist=["add_arguments", "run"])
        except ImportError:
            continue
        p = sub.add_parser(
            name,
            help=(module.__doc__ or "").strip().splitlines()[0] if module.__doc__ else None,
            usage=SCAN_USAGE.format("bench --models MODEL [MODEL ...]").replace(" --model MODEL", "")
            if name == "bench"
            else None,
            allow_abbrev=name != "bench",
        )
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
