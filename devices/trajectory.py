"""A timed joint-space trajectory: what the planner side sends to an arm (simulated or a real driver).

The kinematics, collision checks and motion planning stay on our side (``devices/``); a driver only
executes a :class:`JointTrajectory` and reports its joint state (:class:`devices.protocols.JointArm`).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from planner.validate import checked_array


@dataclass(frozen=True, eq=False)
class JointTrajectory:
    """Joint positions at increasing times.

    joint_names: (n,) the arm's joint names, in the order of the columns.
    times: (K,) float64 seconds from the start, ``times[0] == 0``, strictly increasing, K >= 1.
    positions: (K, n) float64 joint positions, radians (metres for prismatic joints).
    velocities: (K, n) float64 joint velocities at those times (zeros at both ends of a rest-to-rest move).
    """

    joint_names: tuple[str, ...]
    times: NDArray[np.float64]
    positions: NDArray[np.float64]
    velocities: NDArray[np.float64]

    def __post_init__(self) -> None:
        names = tuple(self.joint_names)
        if not names or not all(isinstance(n, str) and n for n in names):
            raise ValueError(f"joint_names: must be non-empty strings, got {self.joint_names!r}")
        object.__setattr__(self, "joint_names", names)
        n = len(names)
        times = checked_array("times", self.times, (None,))
        if len(times) < 1:
            raise ValueError("times: need at least one point")
        if times[0] != 0.0:
            raise ValueError(f"times: must start at 0, got {times[0]!r}")
        if np.any(np.diff(times) <= 0):
            raise ValueError("times: must be strictly increasing")
        object.__setattr__(self, "times", times)
        object.__setattr__(self, "positions", checked_array("positions", self.positions, (len(times), n)))
        object.__setattr__(self, "velocities", checked_array("velocities", self.velocities, (len(times), n)))

    @property
    def duration(self) -> float:
        """Seconds from the first point to the last."""
        return float(self.times[-1])

    @property
    def start(self) -> NDArray[np.float64]:
        """(n,) the first configuration."""
        return self.positions[0]

    @property
    def end(self) -> NDArray[np.float64]:
        """(n,) the last configuration."""
        return self.positions[-1]

    def path_length(self) -> float:
        """Length of the path in joint space (sum of the Euclidean steps between points), radians."""
        return float(np.sum(np.linalg.norm(np.diff(self.positions, axis=0), axis=1)))

    def sample(self, t: float) -> NDArray[np.float64]:
        """(n,) the configuration at time ``t`` (linear between points, clamped to the ends)."""
        t = min(max(float(t), 0.0), self.duration)
        return np.array([np.interp(t, self.times, self.positions[:, j]) for j in range(len(self.joint_names))])

    @staticmethod
    def hold(joint_names: tuple[str, ...], q: NDArray[np.float64]) -> JointTrajectory:
        """A one-point trajectory that stays at ``q`` (a move of zero length)."""
        q = np.asarray(q, dtype=np.float64).reshape(1, -1)
        return JointTrajectory(joint_names, np.zeros(1), q, np.zeros_like(q))

    def truncated(self, t: float) -> JointTrajectory:
        """The first ``t`` seconds (clamped to [0, duration]): where an arm stopped at ``t`` has been. The last
        point is the configuration at ``t``, at rest."""
        t = min(max(float(t), 0.0), self.duration)
        keep = int(np.searchsorted(self.times, t, side="left"))
        if keep == 0:
            return JointTrajectory.hold(self.joint_names, self.positions[0])
        times = np.append(self.times[:keep], t) if self.times[keep - 1] < t else self.times[:keep].copy()
        positions = np.vstack([self.positions[: len(times) - 1], self.sample(t)])
        velocities = np.vstack([self.velocities[: len(times) - 1], np.zeros(len(self.joint_names))])
        return JointTrajectory(self.joint_names, times, positions, velocities)
