"""nbv arms: the arm presets, and where to mount an arm (``nbv arms check NAME_OR_FILE``).

``nbv arms`` lists the presets (``devices/arm/presets.py``). ``nbv arms check NAME_OR_FILE`` reports, for the
candidate hemisphere about an object of ``--object-size`` metres, the share of views the arm reaches (IK, joint
limits, collisions, the plate's turn) from ``--base`` (else it searches mounts beside the plate and suggests the
best), per parallel, with the reasons for the rest (``devices.arm.mount``).
"""

from __future__ import annotations

import argparse
import json
import math
from pathlib import Path

from nbv.options import CliError


def add_arguments(p: argparse.ArgumentParser) -> None:
    sub = p.add_subparsers(dest="arms_command")
    check = sub.add_parser(
        "check", help="the share of the candidate hemisphere an arm reaches; with no --base, search the mount"
    )
    check.add_argument("arm", help="a preset name (nbv arms) or the path of a URDF file")
    check.add_argument("--base", default=None, help="the arm's mount X,Y,Z in the cell's base frame, metres")
    check.add_argument(
        "--object-size", type=float, default=None, help="the object's size, metres (default 0.2 x the preset's scale)"
    )
    check.add_argument("--candidates", type=int, default=None, help="views of the hemisphere (default the planner's)")
    check.add_argument("--config", type=Path, default=None, help="a TOML file: [devices.cell] (the arm) and planner")
    check.add_argument("--json", action="store_true", help="print the report as JSON")


def parse_base(text: str) -> tuple[float, float, float]:
    """``X,Y,Z`` metres; CliError otherwise."""
    try:
        values = tuple(float(v) for v in text.split(","))
    except ValueError:
        raise CliError(f"--base: expected X,Y,Z in metres, got {text!r}") from None
    if len(values) != 3 or not all(math.isfinite(v) for v in values):
        raise CliError(f"--base: expected 3 finite numbers X,Y,Z, got {text!r}")
    return (values[0], values[1], values[2])


def run(args: argparse.Namespace) -> int:
    if args.arms_command is None:
        return list_presets()
    return check(args)


def list_presets() -> int:
    from devices.arm.presets import DEFAULT_PRESET, PRESETS

    for p in PRESETS.values():
        default = " (default)" if p.name == DEFAULT_PRESET else ""
        base = ", ".join(f"{v:g}" for v in p.base)
        print(f"{p.name:7s} {p.title}{default}: {p.dof} joints, flange {p.flange_frame}, mount ({base}) m")
        locked = ", ".join(f"{j} = {v:g}" for j, v in p.locked_joints)
        if locked:
            print(f"        locked: {locked}")
        if p.note:
            print(f"        {p.note}")
    return 0


def check(args: argparse.Namespace) -> int:
    from devices.arm.mount import reach_report, search_mount
    from devices.config import cell_with_arm
    from nbv.options import cell_config_from_args, planner_config_from_args

    if args.arm in ("urdf", "reach_sphere"):
        raise CliError(f"arm: give a preset name or a URDF file, got {args.arm!r}")
    cell = cell_with_arm(cell_config_from_args(argparse.Namespace(config=args.config, arm=None)), args.arm)
    planner = planner_config_from_args(argparse.Namespace(config=args.config))
    scale = cell.arm.defaults.cell_scale
    size = args.object_size if args.object_size is not None else round(0.2 * scale, 4)
    if not (math.isfinite(size) and size > 0):
        raise CliError(f"--object-size: must be > 0 metres, got {size}")
    if scale != 1.0 and args.object_size is None:
        distance = round(planner.candidates.working_distance * scale, 4)
        planner = planner.replace(candidates={"working_distance": distance})
    if args.candidates is not None and args.candidates < 1:
        raise CliError(f"--candidates: must be >= 1, got {args.candidates}")
    if args.base is not None:
        report = reach_report(
            cell.arm, size, base=parse_base(args.base), planner=planner, cell=cell, count=args.candidates
        )
    else:
        report = search_mount(cell.arm, size, planner=planner, cell=cell, count=args.candidates)
    if args.json:
        print(json.dumps(report.to_json(), indent=1))
        return 0
    base = ", ".join(f"{v:g}" for v in report.base)
    how = "suggested mount" if report.searched else "mount"
    print(
        f"{report.arm}: {how} ({base}) m reaches {report.reachable} of {report.candidates} views "
        f"({100 * report.reachable_share:.1f} %) for an object of {size:g} m"
    )
    for elevation, ok, n in report.per_parallel:
        print(f"  elevation {elevation:5.1f} deg: {ok:3d} of {n:3d}")
    for reason, n in report.reasons.items():
        print(f"  unreachable {n:3d}: {reason}")
    if report.searched:
        best = max(s for _, _, s in report.searched)
        print(f"  searched {len(report.searched)} mounts (distance x height), best coarse share {100 * best:.1f} %")
    return 0
