"""Options and errors shared by the ``nbv`` commands (scan, profile, bench): one place, so the commands
import it and not each other."""

from __future__ import annotations

import argparse
import dataclasses
import tomllib
from pathlib import Path
from typing import Any

from devices.calibration_error import CALIBRATIONS, calibration_named
from devices.config import ARM_CHOICES_HELP, CellConfig, cell_with_arm
from devices.sensors.presets import SENSORS, sensor_named
from nbv.flags import add_config_flags, apply_flags, config_fields
from planner.config import PlannerConfig, merge

EXIT_BAD_INPUT = 2


PLANNER_ALIASES: dict[str, list[str]] = {
    "termination.max_views": ["--views"],
    "termination.growth_threshold": ["--growth-threshold"],
    "voxel.resolution": ["--resolution"],
    "voxel.gamma": ["--gamma"],
    "candidates.count": ["--candidates"],
    "candidates.parallels": ["--parallels"],
    "candidates.working_distance": ["--working-distance"],
    "partitions.sectors": ["--partitions"],
    "cluster.t_min": ["--t-min"],
    "cluster.t_max": ["--t-max"],
    "cluster.search": ["--search"],
    "selection.move_cost_weight": ["--move-cost-weight"],
}
"""The short flags of scan, profile and bench before every field had its own: aliases of the generated ones."""


class CliError(Exception):
    """A user-facing error: printed as one line, exit code 2."""


def add_scan_options(p: argparse.ArgumentParser, *, model_required: bool = True, recorded: bool = False) -> None:
    """Options shared by scan, profile and bench (names match the config fields). ``recorded``: ``--model`` or
    ``--recorded DIR`` (a recorded view set, docs/real-data.md), one of them required."""
    if recorded:
        group = p.add_mutually_exclusive_group(required=True)
        group.add_argument("--model", help="a built-in object name or a mesh file (PLY/OBJ/STL/OFF/GLB)")
        group.add_argument(
            "--recorded",
            type=Path,
            metavar="DIR",
            help="scan a recorded view set instead (views.json folder or Stanford range scans): the planner chooses "
            "among its views",
        )
    elif model_required:
        p.add_argument("--model", required=True, help="a built-in object name or a mesh file (PLY/OBJ/STL/OFF/GLB)")
    add_config_flags(p, PlannerConfig, aliases=PLANNER_ALIASES, title="planner")
    p.add_argument("--size", type=float, default=0.2, help="largest extent of the object, m (default %(default)s)")
    p.add_argument("--up", choices=["y", "z"], default="y", help="the mesh file's up axis (default %(default)s)")
    p.add_argument(
        "--yaw", type=float, default=0.0, help="turn the object about the turntable axis before scanning, degrees"
    )
    p.add_argument(
        "--seed",
        type=int,
        default=None,
        help="seed of every random choice: the simulated noise and cluster.seed (default 0, or the --config file's "
        "cluster.seed for the fits)",
    )
    p.add_argument(
        "--depth-noise", type=float, default=0.0, help="std of Gaussian depth noise, m (default %(default)s)"
    )
    p.add_argument("--pose-noise", type=float, default=0.0, help="std of reported-pose translation noise, m")
    p.add_argument(
        "--sensor",
        type=sensor_name,
        default="ideal",
        help=f"the depth sensor's error model: {', '.join(SENSORS)} (default %(default)s)",
    )
    p.add_argument(
        "--calibration",
        type=calibration_name,
        default="none",
        help=f"the cell's calibration and motion error: {', '.join(CALIBRATIONS)} (default %(default)s)",
    )
    p.add_argument(
        "--config",
        type=Path,
        default=None,
        help="a TOML file with planner settings (sections as in the planner config, or under [planner]) and the "
        "cell's ([devices.cell], e.g. [devices.cell.arm], as for nbv serve)",
    )
    p.add_argument(
        "--arm",
        type=arm_name,
        default=None,
        help=f"the cell's arm: {ARM_CHOICES_HELP} (default: the --config file's [devices.cell.arm], else ur5)",
    )
    p.add_argument(
        "--move-capture",
        type=float,
        default=None,
        metavar="HZ",
        help="capture during moves: depth frames per second taken while the arm and the plate move, integrated like "
        "views (devices.cell.move_capture_hz; default: the --config file's, else 0 = off)",
    )
    p.add_argument(
        "--turn-while-moving",
        action="store_true",
        help="the arm cell turns the plate while the arm moves when the arm's path stays clear of the turning "
        "object (arm.turn_while_moving; default: the turn, then the arm)",
    )


def sensor_name(value: str) -> str:
    """argparse type of ``--sensor``: a known name (the error lists them)."""
    try:
        return sensor_named(value).name
    except ValueError as exc:
        raise argparse.ArgumentTypeError(str(exc)) from None


def calibration_name(value: str) -> str:
    """argparse type of ``--calibration``: a known name (the error lists them)."""
    try:
        return calibration_named(value).name
    except ValueError as exc:
        raise argparse.ArgumentTypeError(str(exc)) from None


def arm_name(value: str) -> str:
    """argparse type of ``--arm``: a preset, a URDF file, 'urdf' or 'reach_sphere' (the error lists the presets)."""
    try:
        cell_with_arm(CellConfig(), value)
    except ValueError as exc:
        raise argparse.ArgumentTypeError(str(exc).removeprefix("--arm: ")) from None
    return value


def read_config_file(path: Path) -> tuple[dict[str, Any], dict[str, Any]]:
    """(planner settings, cell settings) of a ``--config`` TOML file: the planner's sections at the top level or
    under ``[planner]``, the cell's under ``[devices.cell]`` (the layout of ``nbv serve --config``; ``[cell]``
    too). ValueError for invalid TOML or devices settings other than the cell's."""
    with open(path, "rb") as fh:
        try:
            data = tomllib.load(fh)
        except tomllib.TOMLDecodeError as exc:
            raise ValueError(f"{path}: invalid TOML ({exc})") from None
    planner = dict(data.pop("planner", {}))
    cell = dict(data.pop("cell", {}))
    devices = data.pop("devices", {})
    if not isinstance(devices, dict):
        raise ValueError("devices: expected a table")
    other = sorted(set(devices) - {"cell"})
    if other:
        raise ValueError(f"devices.{other[0]}: not a setting of this command (only [devices.cell] is read)")
    cell.update(devices.get("cell", {}))
    planner.update(data)
    return planner, cell


def cell_config_from_args(args: argparse.Namespace) -> CellConfig:
    """The cell of a simulated run: the ``--config`` file's ``[devices.cell]``, then ``--arm``. ValueError naming
    the field on bad values."""
    path = getattr(args, "config", None)
    cell = CellConfig()
    if path:
        _, data = read_config_file(path)
        cell = merge(cell, data, "devices.cell.")
    hz = getattr(args, "move_capture", None)
    if hz is not None:
        cell = dataclasses.replace(cell, move_capture_hz=float(hz))  # validated: cell.move_capture_hz
    return cell_with_arm(cell, getattr(args, "arm", None))


def seed_of(args: argparse.Namespace) -> int:
    """``--seed``, 0 when not given."""
    return 0 if getattr(args, "seed", None) is None else int(args.seed)


def planner_config_from_args(args: argparse.Namespace) -> PlannerConfig:
    """PlannerConfig from --config, then ``--seed`` (the fits' seed), then the config flags (flags win).
    ValueError on bad values."""
    config = (
        PlannerConfig.from_dict(read_config_file(args.config)[0]) if getattr(args, "config", None) else PlannerConfig()
    )
    seed = getattr(args, "seed", None)
    if seed is not None:
        config = config.replace(cluster={"seed": seed})
    return apply_flags(config, args, config_fields(PlannerConfig))
