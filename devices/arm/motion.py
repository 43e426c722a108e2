"""Joint-space motion from the current configuration to a target: a collision-free path, then timed.

Path: the straight joint-space line when it is free (checked every ``ArmConfig.path_resolution_deg`` of the
largest joint step), else our RRT-Connect in the joint box, then a greedy shortcut. Deterministic: the samples
come from a generator seeded by ``seed`` and the inputs, and the search stops after
``ArmConfig.planning_checks`` collision checks (then ``no_path``), so the same inputs give bit-identical
waypoints (and trajectory) on an idle or a loaded machine. ``ArmConfig.planning_time`` is only a hang guard:
wall-clock seconds after which the query gives up (generous: it never decides on a healthy machine).
(OMPL's RRT-Connect cannot be made reproducible through its Python bindings: they do not expose
``StateSpace::setStateSamplerAllocator``, and its random generators are seeded per process.)

Timing: ruckig, rest to rest along every segment of the path with phase synchronisation (all joints start and
stop together, so the arm stays on the checked straight segment), under the arm's velocity and acceleration
limits; sampled every ``SAMPLE_DT`` seconds into a :class:`devices.trajectory.JointTrajectory`.
"""

from __future__ import annotations

import itertools
import math
import time
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from devices.arm.collision import CollisionWorld
from devices.arm.model import ArmModel
from devices.trajectory import JointTrajectory

SAMPLE_DT = 0.04
"""Seconds between the points of a timed trajectory (25 Hz: smooth enough to animate and to replay)."""
RRT_STEP = 0.5
"""Largest joint step of one RRT-Connect extension, radians (its edge is checked every path resolution)."""


@dataclass(frozen=True, eq=False)
class PathPlan:
    """A collision-free joint path. waypoints: (K, n) float64, K >= 2 (start and goal included), radians.

    method: 'straight' or 'rrt_connect'. checks: collision checks the search spent (0 for a straight line;
    deterministic). seconds: wall time spent planning (not deterministic: the machine's load).
    """

    waypoints: NDArray[np.float64]
    method: str
    seconds: float
    checks: int = 0


class NoPathError(Exception):
    """No collision-free path within the planning budget (the view is ``no_path``)."""


def plan_path(
    world: CollisionWorld,
    q_from: NDArray[np.float64],
    q_to: NDArray[np.float64],
    plate_angle: float,
    *,
    seed: int = 0,
) -> PathPlan:
    """A free path q_from -> q_to (both (n,)) with the plate at ``plate_angle``; NoPathError if none within
    ``arm.planning_checks`` collision checks (or, as a hang guard only, ``arm.planning_time`` seconds).
    A pure function of its arguments and the world's obstacles (``seed`` varies the search)."""
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
    search = _RRTConnect(world, plate_angle, resolution, cfg.planning_checks, t0 + cfg.planning_time, seed)
    raw = search.solve(q_from, q_to)
    if raw is None:
        budget = f"{cfg.planning_checks} collision checks"
        if search.timed_out:
            budget = f"its wall-clock guard of {cfg.planning_time:g} s ({search.checks} collision checks)"
        raise NoPathError(f"no_path: RRT-Connect found no collision-free path within {budget}")
    waypoints = _shortcut(world, raw, plate_angle, resolution)
    for a, b in itertools.pairwise(waypoints):  # every edge was checked; the dense check of the result decides
        if world.path_collision(a, b, plate_angle, resolution) is not None:  # pragma: no cover - defensive
            raise NoPathError("no_path: the shortened path touches an obstacle between its checked states")
    return PathPlan(waypoints, "rrt_connect", time.perf_counter() - t0, search.checks)


def _shortcut(
    world: CollisionWorld, waypoints: NDArray[np.float64], plate_angle: float, resolution: float
) -> NDArray[np.float64]:
    """(K, n) -> (K', n), K' <= K: from each kept waypoint, straight to the farthest later waypoint whose segment
    is free (``world.path_collision`` every ``resolution`` radians); deterministic, keeps start and goal."""
    kept = [0]
    while kept[-1] < len(waypoints) - 1:
        i = kept[-1]
        j = len(waypoints) - 1
        while j > i + 1 and world.path_collision(waypoints[i], waypoints[j], plate_angle, resolution) is not None:
            j -= 1
        kept.append(j)
    return waypoints[kept].copy()


class _Tree:
    """An RRT: nodes (m, n) in a growing array, each node's parent index (-1 for the root)."""

    def __init__(self, root: NDArray[np.float64]) -> None:
        self.nodes = np.empty((64, root.shape[0]))
        self.nodes[0] = root
        self.parents = [-1]

    def __len__(self) -> int:
        return len(self.parents)

    def nearest(self, q: NDArray[np.float64]) -> int:
        """Index of the node nearest ``q`` (Euclidean in joint space; ties: the oldest)."""
        d = self.nodes[: len(self)] - q
        return int(np.argmin(np.einsum("ij,ij->i", d, d)))

    def add(self, q: NDArray[np.float64], parent: int) -> int:
        if len(self) == self.nodes.shape[0]:
            self.nodes = np.concatenate([self.nodes, np.empty_like(self.nodes)])
        self.nodes[len(self)] = q
        self.parents.append(parent)
        return len(self) - 1

    def branch(self, i: int) -> list[NDArray[np.float64]]:
        """The nodes from node ``i`` back to the root."""
        out = []
        while i >= 0:
            out.append(self.nodes[i].copy())
            i = self.parents[i]
        return out


class _RRTConnect:
    """Kuffner and LaValle's RRT-Connect (2000) in the joint box, with a collision-check budget.

    Samples: uniform in the joint limits from ``numpy.random.default_rng`` seeded by ``seed``, the start, the
    goal and the plate angle. An extension moves at most ``RRT_STEP`` (largest joint) toward the sample; its
    edge is checked every ``resolution`` radians. Stops when the trees meet, after ``budget`` collision checks,
    or at the wall-clock ``deadline`` (``time.perf_counter()``; a hang guard, checked between extensions).
    """

    def __init__(
        self, world: CollisionWorld, plate_angle: float, resolution: float, budget: int, deadline: float, seed: int
    ) -> None:
        self.world, self.angle, self.resolution = world, plate_angle, resolution
        self.budget, self.deadline, self.seed = budget, deadline, seed
        self.checks = 0
        self.timed_out = False

    def _free(self, qa: NDArray[np.float64], qb: NDArray[np.float64]) -> bool:
        """Whether the segment qa -> qb is free (qa is known to be), every ``resolution`` like ``path_collision``;
        False too once the budget is spent."""
        delta = qb - qa
        steps = max(1, math.ceil(float(np.max(np.abs(delta))) / self.resolution))
        for k in range(1, steps + 1):
            if self.checks >= self.budget:
                return False
            self.checks += 1
            if self.world.collision(qa + (k / steps) * delta, self.angle) is not None:
                return False
        return True

    def _extend(self, tree: _Tree, q: NDArray[np.float64]) -> tuple[int, bool]:
        """One step of ``tree`` toward ``q``: (the new node or -1 when blocked, whether it is ``q``)."""
        i = tree.nearest(q)
        near = tree.nodes[i]
        delta = q - near
        largest = float(np.max(np.abs(delta)))
        reached = largest <= RRT_STEP
        target = q if reached else near + delta * (RRT_STEP / largest)
        if not self._free(near, target):
            return -1, False
        return tree.add(target, i), reached

    def _spent(self) -> bool:
        if time.perf_counter() > self.deadline:
            self.timed_out = True
        return self.timed_out or self.checks >= self.budget

    def solve(self, q_from: NDArray[np.float64], q_to: NDArray[np.float64]) -> NDArray[np.float64] | None:
        """Waypoints (K, n) from ``q_from`` to ``q_to`` (both free; the tree nodes on the way), or None."""
        arm = self.world.arm
        words = np.frombuffer(np.concatenate([q_from, q_to, [self.angle]]).tobytes(), dtype=np.uint32)
        rng = np.random.default_rng([int(self.seed) & 0xFFFFFFFF, *words.tolist()])
        a, b = _Tree(q_from), _Tree(q_to)
        a_is_start = True
        while not self._spent():
            new, _ = self._extend(a, rng.uniform(arm.lower, arm.upper))
            if new >= 0:
                reached = False
                while not reached and not self._spent():  # connect: b grows toward the new node until blocked
                    other, reached = self._extend(b, a.nodes[new])
                    if other < 0:
                        break
                if reached:  # b's newest node is a's node ``new``
                    ends = (a.branch(new), b.branch(len(b) - 1))
                    start, goal = ends if a_is_start else ends[::-1]
                    out = np.array(start[::-1] + goal[1:])
                    out[0], out[-1] = q_from, q_to
                    return out
            a, b = b, a
            a_is_start = not a_is_start
        return None


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
