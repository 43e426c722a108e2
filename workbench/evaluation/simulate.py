"""One simulated scan of a model, the library half of ``nbv scan`` / ``nbv profile`` and of the bench: load and
place the mesh, build the simulated cell, run Algorithm 1 (:func:`workbench.evaluation.scan.run_scan`), measure
coverage and, optionally, the reachable-coverage ceiling."""

from __future__ import annotations

import dataclasses
import math
import time
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

import numpy as np

from planner import DepthFrame, Planner, PlannerConfig, PlanResult
from workbench.evaluation.accuracy import GroundTruth
from workbench.evaluation.scan import IterationRecord, ScanResult, run_scan


@dataclass
class SimScan:
    """A finished simulated scan with what is needed to report on it."""

    model: str
    config: PlannerConfig
    result: ScanResult
    planner: Planner
    reachable_coverage: float | None
    surface_samples: np.ndarray
    cell: Any
    mesh: Any = None
    """The placed (and turned) ground-truth mesh in the table frame."""
    ceiling_seconds: float = 0.0
    """How long the reachable-coverage ceiling took (0 when not computed)."""


def simulate(
    model: str,
    config: PlannerConfig,
    *,
    planner_name: str = "projection",
    size: float = 0.2,
    up: str = "y",
    yaw_deg: float = 0.0,
    seed: int = 0,
    depth_noise: float = 0.0,
    pose_noise: float = 0.0,
    reachable: bool = True,
    keep_plans: bool = False,
    on_start: Callable[[str], None] | None = None,
    on_iteration: Callable[[IterationRecord, PlanResult], None] | None = None,
    mesh: Any = None,
    arm: str | None = "urdf",
    on_frame: Callable[[DepthFrame], None] | None = None,
    sensor: str = "ideal",
    calibration: str = "none",
    turn_while_moving: bool = False,
    cell: Any = None,
    on_move_frame: Callable[[DepthFrame], None] | None = None,
) -> SimScan:
    """Load ``model``, build the simulated cell, run Algorithm 1, measure coverage.

    ``yaw_deg`` turns the placed object about the turntable axis (z through the plate
    centre) before the scan: the same object, set down another way round. ``mesh``: the
    placed mesh already loaded (then ``model`` is only its name; ``up`` and ``size`` are not
    applied again). ``reachable``: also compute the reachable-coverage ceiling of the object
    and placement (:func:`workbench.evaluation.object_ceiling.object_ceiling`, independent of the run).
    ``on_start``: told the model's display name before the scan; ``on_iteration``: called after every
    iteration with its record and plan. ``arm``: an arm preset ('ur5', 'panda', ...: ``devices/arm/presets.py``) or the
    path of a URDF file (IK, collision checks and joint trajectories), 'urdf' (the arm of ``cell``, the UR5 by
    default) or 'reach_sphere' (``devices.config.cell_with_arm``). ``cell``: the cell's settings
    (``devices.config.CellConfig``, e.g. a config file's ``[devices.cell]``; default the default cell). ``on_frame``: hears each frame with its registered pose (``run_scan``); ``on_move_frame``: each frame kept from
    the moves (capture during moves: ``cell.move_capture_hz``).
    ``turn_while_moving``: the UR5 cell turns the plate while the arm moves when the arm's path stays clear of the
    turning object (``ArmConfig.turn_while_moving``).
    ``sensor``, ``calibration``: the camera's sensor model and the cell's calibration error by name
    (``CameraConfig.sensor`` / ``.calibration``); the planner's noise settings follow them
    (``devices.planner_noise.planner_config_for``). Accuracy per view against the mesh is in
    ``IterationRecord.accuracy``.
    """
    from devices.builtins import resolve_model
    from devices.config import CameraConfig, CellConfig, cell_with_arm
    from devices.mesh import sample_surface, turned_about_plate_axis
    from devices.planner_noise import planner_config_for
    from devices.sim import make_sim_cell
    from workbench.evaluation.object_ceiling import object_ceiling

    if not (math.isfinite(size) and size > 0):
        raise ValueError(f"--size: must be > 0, got {size}")
    if depth_noise < 0 or pose_noise < 0:
        raise ValueError("--depth-noise and --pose-noise must be >= 0")
    if not math.isfinite(yaw_deg):
        raise ValueError(f"--yaw: must be finite, got {yaw_deg}")
    if mesh is None:
        name, mesh = resolve_model(model, up=up, size=size)  # type: ignore[arg-type]
    else:
        name = model
    if yaw_deg % 360.0 != 0.0:
        mesh = turned_about_plate_axis(mesh, yaw_deg)
    camera = CameraConfig(
        depth_noise_std=depth_noise, pose_noise_translation=pose_noise, sensor=sensor, calibration=calibration
    )
    config = planner_config_for(config, camera)
    base_cell: CellConfig = cell if cell is not None else CellConfig()
    cell_config = cell_with_arm(base_cell, arm)
    if turn_while_moving:
        cell_config = dataclasses.replace(cell_config, arm=dataclasses.replace(cell_config.arm, turn_while_moving=True))
    cell = make_sim_cell(mesh, camera, cell_config, seed=seed)
    samples = sample_surface(mesh, 10_000, seed=seed)
    planner = Planner(config, evaluator=planner_name)

    if on_start is not None:
        on_start(name)
    truth = GroundTruth.of(mesh, samples)
    result = run_scan(
        planner,
        cell,
        samples,
        on_iteration=on_iteration,
        keep_plans=keep_plans,
        on_frame=on_frame,
        truth=truth,
        on_move_frame=on_move_frame,
    )
    ceiling, ceiling_seconds = None, 0.0
    if reachable:
        t0 = time.perf_counter()
        ceiling = object_ceiling(mesh, cell, CameraConfig(), config).coverage
        ceiling_seconds = time.perf_counter() - t0
    return SimScan(name, config, result, planner, ceiling, samples, cell, mesh, ceiling_seconds)
