"""A simulated joint arm: executes joint trajectories (at once, or in real time with progress), reports its joints.

It implements :class:`devices.protocols.JointArm`, the shape of a real driver. Fault injection: set ``fail_next``
to an exception; the next ``execute`` raises it without moving. ``stop()`` (from another thread) halts a
real-time execution where it is; the arm then raises :class:`DeviceError` and stays at that configuration.
"""

from __future__ import annotations

import threading
import time
from collections.abc import Callable

import numpy as np
from numpy.typing import NDArray

from devices.protocols import DeviceError
from devices.trajectory import JointTrajectory
from planner.types import Pose

START_TOLERANCE = 1e-3
"""A trajectory must start within this many radians (every joint) of the arm's configuration."""


class SimulatedJointArm:
    """joint_names: (n,) names. q: (n,) initial configuration, radians.

    real_time: play trajectories at their own speed (times ``time_scale``), else jump to the end at once.
    on_progress: called with (t, q) at every trajectory point reached (t seconds, q (n,)).
    pose_of: forward kinematics, q -> ``T_base_camera``; gives the arm a ``pose`` like a pose arm's (optional).
    """

    def __init__(
        self,
        joint_names: tuple[str, ...],
        q: NDArray[np.float64],
        *,
        real_time: bool = False,
        time_scale: float = 1.0,
        on_progress: Callable[[float, NDArray[np.float64]], None] | None = None,
        pose_of: Callable[[NDArray[np.float64]], Pose] | None = None,
    ) -> None:
        self._names = tuple(joint_names)
        q = np.asarray(q, dtype=np.float64)
        if q.shape != (len(self._names),) or not np.all(np.isfinite(q)):
            raise ValueError(f"q: expected ({len(self._names)},) finite joint positions, got shape {q.shape}")
        if not time_scale > 0:
            raise ValueError(f"time_scale: must be > 0, got {time_scale!r}")
        self._q = q.copy()
        self.real_time = real_time
        self.time_scale = float(time_scale)
        self.on_progress = on_progress
        self.pose_of = pose_of
        self.fail_next: Exception | None = None
        self.moves = 0
        self._lock = threading.Lock()
        self._stop = threading.Event()

    @property
    def joint_names(self) -> tuple[str, ...]:
        return self._names

    @property
    def pose(self) -> Pose:
        """``T_base_camera`` of the current joints (needs ``pose_of``)."""
        if self.pose_of is None:
            raise AttributeError("pose: this joint arm has no forward kinematics (pose_of)")
        return self.pose_of(self.joint_positions())

    def joint_positions(self) -> NDArray[np.float64]:
        with self._lock:
            return self._q.copy()

    def reset(self, q: NDArray[np.float64]) -> None:
        """Put the arm at (n,) ``q`` without a move (start-up, or a test)."""
        q = np.asarray(q, dtype=np.float64)
        if q.shape != self._q.shape:
            raise ValueError(f"q: expected shape {self._q.shape}, got {q.shape}")
        with self._lock:
            self._q = q.copy()

    def execute(self, trajectory: JointTrajectory) -> None:
        """Follow ``trajectory`` to its end. DeviceError if it is for other joints or starts elsewhere."""
        if not isinstance(trajectory, JointTrajectory):
            raise ValueError(f"trajectory: expected a JointTrajectory, got {type(trajectory).__name__}")
        if trajectory.joint_names != self._names:
            raise DeviceError(f"arm: trajectory joints {trajectory.joint_names} are not this arm's {self._names}")
        gap = float(np.max(np.abs(trajectory.start - self.joint_positions())))
        if gap > START_TOLERANCE:
            raise DeviceError(f"arm: trajectory starts {gap:.4f} rad away from the arm's configuration")
        if self.fail_next is not None:
            exc, self.fail_next = self.fail_next, None
            raise exc
        self._stop.clear()
        if not self.real_time:
            self._set(trajectory.end, trajectory.duration)
            self.moves += 1
            return
        t0 = time.monotonic()
        for t, q in zip(trajectory.times, trajectory.positions, strict=True):
            while (wait := t * self.time_scale - (time.monotonic() - t0)) > 0:
                if self._stop.wait(min(wait, 0.05)):
                    break
            if self._stop.is_set():
                elapsed = (time.monotonic() - t0) / self.time_scale
                self._set(trajectory.sample(elapsed), elapsed)
                raise DeviceError(f"arm: stopped after {elapsed:.2f} s of {trajectory.duration:.2f} s")
            self._set(q, float(t))
        self.moves += 1

    def stop(self) -> None:
        self._stop.set()

    def _set(self, q: NDArray[np.float64], t: float) -> None:
        with self._lock:
            self._q = np.array(q, dtype=np.float64)
        if self.on_progress is not None:
            self.on_progress(t, self._q.copy())
