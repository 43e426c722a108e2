"""Options and errors shared by the ``nbv`` commands (scan, profile, bench): one place, so the commands
import it and not each other."""

from __future__ import annotations

import argparse
from pathlib import Path
from typing import Any

from devices.calibration_error import CALIBRATIONS, calibration_named
from devices.sensors.presets import SENSORS, sensor_named
from planner.config import PlannerConfig

EXIT_BAD_INPUT = 2


class CliError(Exception):
    """A user-facing error: printed as one line, exit code 2."""


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
    p.add_argument(
        "--sensor",
        type=sensor_name,
        default="ideal",
        help=f"the depth sensor's error model: {', '.join(SENSORS)} (default ideal)",
    )
    p.add_argument(
        "--calibration",
        type=calibration_name,
        default="none",
        help=f"the cell's calibration and motion error: {', '.join(CALIBRATIONS)} (default none)",
    )
    p.add_argument("--config", type=Path, default=None, help="a TOML file with planner settings")
    p.add_argument(
        "--arm",
        choices=["urdf", "reach_sphere"],
        default="urdf",
        help="the cell's arm: the UR5 model with IK, collisions and trajectories (default) or the reach sphere",
    )
    p.add_argument(
        "--turn-while-moving",
        action="store_true",
        help="the UR5 cell turns the plate while the arm moves when the arm's path stays clear of the turning "
        "object (arm.turn_while_moving; default: the turn, then the arm)",
    )
    p.add_argument(
        "--move-cost-weight",
        type=float,
        default=None,
        help="trade F against move duration (selection.move_cost_weight, default 0 = the paper's rule)",
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
    put("selection", "move_cost_weight", args.move_cost_weight)
    return config.replace(**overrides)
