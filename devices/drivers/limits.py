"""Joint limits a trajectory must keep before any arm driver sends it (positions, speeds, accelerations).

The speeds and accelerations checked are those the arm will really see: the planned ones times the
driver's speed scale (``speed_fraction``: a trajectory slowed to a quarter moves at a quarter of its
speeds and a sixteenth of its accelerations).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from devices.protocols import DeviceError
from devices.trajectory import JointTrajectory


class LimitError(DeviceError):
    """A trajectory breaks the configured joint limits; nothing was sent to the arm."""


@dataclass(frozen=True)
class JointLimits:
    """Limits per joint, radians (code units; the cell file gives degrees).

    lower, upper: (n,) position bounds. max_speed: the fastest any joint may turn, rad/s.
    max_acceleration: rad/s^2.
    """

    lower: tuple[float, ...]
    upper: tuple[float, ...]
    max_speed: float
    max_acceleration: float

    def __post_init__(self) -> None:
        if len(self.lower) != len(self.upper) or not self.lower:
            raise ValueError("limits: lower and upper need one bound per joint")
        if any(not lo < hi for lo, hi in zip(self.lower, self.upper, strict=True)):
            raise ValueError("limits: every lower bound must be below its upper bound")
        for name in ("max_speed", "max_acceleration"):
            v = getattr(self, name)
            if not (math.isfinite(v) and v > 0):
                raise ValueError(f"limits.{name}: must be > 0, got {v!r}")

    def check_positions(self, trajectory: JointTrajectory) -> None:
        """Raise LimitError naming the joint, the time and the angle if ``trajectory`` leaves the bounds."""
        names = trajectory.joint_names
        if len(names) != len(self.lower):
            raise LimitError(f"limits: trajectory has {len(names)} joints, the arm {len(self.lower)}")
        q = trajectory.positions
        lower, upper = np.asarray(self.lower), np.asarray(self.upper)
        for bad, bound, word in ((q < lower - 1e-9, lower, "below"), (q > upper + 1e-9, upper, "above")):
            if bad.any():
                k, j = np.argwhere(bad)[0]
                raise LimitError(
                    f"limits: {names[j]} at {math.degrees(q[k, j]):.2f} deg (t = {trajectory.times[k]:.2f} s) is "
                    f"{word} its bound {math.degrees(bound[j]):.2f} deg"
                )

    def check(self, trajectory: JointTrajectory, speed_fraction: float = 1.0) -> None:
        """Raise LimitError naming the joint, the time and the value if ``trajectory`` at ``speed_fraction``
        of its speed leaves the bounds or turns or accelerates a joint faster than allowed."""
        if not (math.isfinite(speed_fraction) and speed_fraction > 0):
            raise ValueError(f"speed_fraction: must be > 0, got {speed_fraction!r}")
        self.check_positions(trajectory)
        names = trajectory.joint_names
        speed = np.abs(trajectory.velocities) * speed_fraction
        if speed.size and speed.max() > self.max_speed * (1 + 1e-9):
            k, j = np.unravel_index(int(np.argmax(speed)), speed.shape)
            raise LimitError(
                f"limits: {names[j]} turns at {math.degrees(speed[k, j]):.1f} deg/s (t = {trajectory.times[k]:.2f} s), "
                f"above max_joint_speed_deg {math.degrees(self.max_speed):.1f}"
            )
        if len(trajectory.times) > 1:
            dt = np.diff(trajectory.times)[:, None] / speed_fraction
            acc = np.abs(np.diff(trajectory.velocities, axis=0) * speed_fraction) / dt
            if acc.max() > self.max_acceleration * (1 + 1e-9):
                k, j = np.unravel_index(int(np.argmax(acc)), acc.shape)
                raise LimitError(
                    f"limits: {names[j]} accelerates at {math.degrees(acc[k, j]):.1f} deg/s^2 "
                    f"(t = {trajectory.times[k]:.2f} s), above max_joint_acceleration_deg "
                    f"{math.degrees(self.max_acceleration):.1f}"
                )
