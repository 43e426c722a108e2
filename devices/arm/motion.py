"""Joint-space motion from the current configuration to a target: a collision-free path, then timed.

Path: the straight joint-space line when it is free (checked every ``ArmConfig.path_resolution_deg`` of the
largest joint step), else OMPL's RRT-Connect in the joint box with its path simplifier, within
``ArmConfig.planning_time`` (no path in time -> ``no_path``, never a hang).

Timing: ruckig, rest to rest along every segment of the path with phase synchronisation (all joints start and
stop together, so the arm stays on the checked straight segment), under the arm's velocity and acceleration
limits; sampled every ``SAMPLE_DT`` seconds into a :class:`devices.trajectory.JointTrajectory`.
"""

from __future__ import annotations

import itertools
import math
from dataclasses import dataclass
from typing import Any

import numpy as np
from numpy.typing import NDArray

from devices.arm.collision import CollisionWorld
from devices.arm.model import ArmModel
from devices.trajectory import JointTrajectory

SAMPLE_DT = 0.04
"""Seconds between the points of a timed trajectory (25 Hz: smooth enough to animate and to replay)."""


@dataclass(frozen=True, eq=False)
class PathPlan:
    """A collision-free joint path. waypoints: (K, n) float64, K >= 2 (start and goal included), radians.

    method: 'straight' or 'rrt_connect'. seconds: planning time spent.
    """

    waypoints: NDArray[np.float64]
    method: str
    seconds: float


class NoPathError(Exception):
    """No collision-free path was found within the planning time (the view is ``no_path``)."""


def plan_path(
    world: CollisionWorld,
    q_from: NDArray[np.float64],
    q_to: NDArray[np.float64],
    plate_angle: float,
    *,
    seed: int = 0,
) -> PathPlan:
    """A free path q_from -> q_to (both (n,)) with the plate at ``plate_angle``; NoPathError if none in time."""
    import time

    cfg = world.arm.config
    resolution = math.radians(cfg.path_resolution_deg)
    t0 = time.perf_counter()
    q_from = np.asarray(q_from, dtype=np.float64)
    q_to = np.asarray(q_to, dtype=np.float64)
    for name, q in (("start", q_from), ("goal", q_to)):
        reason = world.collision(q, plate_angle)
        if reason is not None:
            raise NoPathError(f"no_path: the {name} configuration is in collision ({reason})")
    if world.path_collision(q_from, q_to, plate_angle, resolution) is None:
        return PathPlan(np.stack([q_from, q_to]), "straight", time.perf_counter() - t0)
    waypoints = _rrt_connect(world, q_from, q_to, plate_angle, resolution, cfg.planning_time, seed)
    if waypoints is None:
        raise NoPathError(f"no_path: RRT-Connect found no collision-free path in {cfg.planning_time:g} s")
    for a, b in itertools.pairwise(waypoints):  # OMPL checked it; the dense check decides
        if world.path_collision(a, b, plate_angle, resolution) is not None:
            raise NoPathError("no_path: the simplified path touches an obstacle between its checked states")
    return PathPlan(waypoints, "rrt_connect", time.perf_counter() - t0)


def _rrt_connect(
    world: CollisionWorld,
    q_from: NDArray[np.float64],
    q_to: NDArray[np.float64],
    plate_angle: float,
    resolution: float,
    time_limit: float,
    seed: int,
) -> NDArray[np.float64] | None:
    from ompl import base as ob
    from ompl import geometric as og
    from ompl import util as ou

    ou.setLogLevel(ou.LogLevel.LOG_ERROR)
    arm = world.arm
    n = arm.nq
    space = ob.RealVectorStateSpace(n)
    bounds = ob.RealVectorBounds(n)
    for j in range(n):
        bounds.setLow(j, float(arm.lower[j]))
        bounds.setHigh(j, float(arm.upper[j]))
    space.setBounds(bounds)
    setup = og.SimpleSetup(space)
    q = np.empty(n)

    def valid(state: object) -> bool:
        for j in range(n):
            q[j] = state[j]  # type: ignore[index]
        return world.collision(q, plate_angle) is None

    setup.setStateValidityChecker(valid)
    info = setup.getSpaceInformation()
    info.setStateValidityCheckingResolution(resolution / max(space.getMaximumExtent(), 1e-9))
    start: Any = space.allocState()
    goal: Any = space.allocState()
    for j in range(n):
        start[j], goal[j] = float(q_from[j]), float(q_to[j])
    setup.setStartAndGoalStates(start, goal)
    setup.setPlanner(og.RRTConnect(info))
    if not setup.solve(time_limit) or not setup.haveExactSolutionPath():
        return None
    setup.simplifySolution(max(0.05, 0.25 * time_limit))
    path: Any = setup.getSolutionPath()
    points = np.array([[path.getState(i)[j] for j in range(n)] for i in range(path.getStateCount())])
    points[0], points[-1] = q_from, q_to
    return points


def time_path(arm: ArmModel, waypoints: NDArray[np.float64]) -> JointTrajectory:
    """The path (K, n) timed with ruckig under ``arm.velocity`` / ``arm.acceleration``, at rest at every waypoint."""
    from ruckig import InputParameter, Result, Ruckig, Synchronization, Trajectory

    waypoints = np.asarray(waypoints, dtype=np.float64)
    n = waypoints.shape[1]
    names = arm.joint_names
    times: list[float] = [0.0]
    positions: list[NDArray[np.float64]] = [waypoints[0]]
    velocities: list[NDArray[np.float64]] = [np.zeros(n)]
    otg = Ruckig(n)
    t_offset = 0.0
    for a, b in itertools.pairwise(waypoints):
        if float(np.max(np.abs(b - a))) < 1e-9:
            continue
        inp = InputParameter(n)
        inp.current_position = a.tolist()
        inp.target_position = b.tolist()
        inp.max_velocity = arm.velocity.tolist()
        inp.max_acceleration = arm.acceleration.tolist()
        inp.max_jerk = [math.inf] * n
        inp.synchronization = Synchronization.Phase
        trajectory = Trajectory(n)
        result = otg.calculate(inp, trajectory)
        if result not in (Result.Working, Result.Finished):
            raise ValueError(f"trajectory: ruckig could not time a segment ({result})")
        duration = float(trajectory.duration)
        steps = max(1, math.ceil(duration / SAMPLE_DT))
        for t in np.linspace(0.0, duration, steps + 1)[1:]:
            p, v, _ = trajectory.at_time(float(t))
            times.append(t_offset + float(t))
            positions.append(np.array(p))
            velocities.append(np.array(v))
        positions[-1], velocities[-1] = b.copy(), np.zeros(n)
        t_offset += duration
    return JointTrajectory(names, np.array(times), np.array(positions), np.array(velocities))
