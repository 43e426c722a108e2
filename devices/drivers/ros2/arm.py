"""A robot arm on ROS 2 topics: joints from ``sensor_msgs/JointState``, moves as ``trajectory_msgs/JointTrajectory``
to a ros2_control joint trajectory controller (``ur_robot_driver``, ``franka_ros2``, xArm, Kinova).

The trajectory is the one our planner computed (kinematics, collision checks and timing stay on our side); the
controller interpolates it. Before it is sent: the joint names must be the configured ones and the trajectory must
start within ``start_tolerance_deg`` of the arm's joints. While it runs, every joint state is checked:

- a deviation from the path (the nearest point of the trajectory so far) beyond ``path_tolerance_deg``: a jump, a
  collision, a controller that does something else;
- no joint state for ``state_timeout_s``: the driver or the network is gone;
- not at the goal ``duration * 1.5 + timeout_margin_s`` after the start: too slow, or the trajectory was never
  executed (no controller, a controller that refused it).

Each is an :class:`devices.drivers.common.ArmFaultError` (the reason and the last joints), after the arm is told to
stop: an empty ``JointTrajectory``, which a joint trajectory controller takes as "hold where you are". The move is
done when the joints are within ``goal_tolerance_deg`` of the goal and stay there for ``settle_s``; the stamp of
that joint state is the node's ``settled_stamp`` (a capture takes an image stamped after it).

For move capture, :meth:`Ros2Arm.record_joints` keeps every joint state with its header stamp (from the latest one
before the move on): the history a frame's pose is interpolated from.
"""

from __future__ import annotations

import contextlib
import math
import threading
import time
from dataclasses import dataclass
from typing import Any

import numpy as np
from numpy.typing import NDArray

from devices.drivers.common import ArmFaultError
from devices.drivers.ros2.dds import DdsConfig, Subscription, acquire, await_subscriber, release
from devices.movestream import StampedSeries
from devices.protocols import DeviceError
from devices.trajectory import JointTrajectory
from planner.validate import finite, require

UR_JOINTS = (
    "shoulder_pan_joint",
    "shoulder_lift_joint",
    "elbow_joint",
    "wrist_1_joint",
    "wrist_2_joint",
    "wrist_3_joint",
)


@dataclass(frozen=True)
class Ros2ArmConfig(DdsConfig):
    """``[devices.arm] driver = "ros2"``: the controller's topics and the checks of a move (defaults:
    ``ur_robot_driver``'s scaled joint trajectory controller; for a Franka ``franka_ros2``'s
    ``/fr3_arm_controller/joint_trajectory`` and the ``fr3_joint1`` ... ``fr3_joint7`` names)."""

    joint_names: tuple[str, ...] = UR_JOINTS
    """The arm's joints in the arm model's order (the URDF's names, as the controller knows them)."""
    command_topic: str = "/scaled_joint_trajectory_controller/joint_trajectory"
    """The joint trajectory controller's ``trajectory_msgs/JointTrajectory`` topic."""
    state_topic: str = "/joint_states"
    """The ``sensor_msgs/JointState`` topic carrying (at least) these joints."""
    max_joint_speed_deg: float = 60.0
    """Planned joint speeds are kept under this, deg/s."""
    start_tolerance_deg: float = 1.0
    """A trajectory must start within this of the arm's joints (largest joint difference), degrees."""
    goal_tolerance_deg: float = 0.5
    """The move is done within this of the goal (every joint), degrees."""
    path_tolerance_deg: float = 5.0
    """Largest distance of the joints from the trajectory's path while moving (any joint), degrees."""
    settle_s: float = 0.2
    """The joints must stay within the goal tolerance this long, seconds."""
    state_timeout_s: float = 1.0
    """No joint state for this long is a fault (and at start: no arm), seconds."""
    timeout_margin_s: float = 5.0
    """A move may take its duration times 1.5 plus this before it counts as too slow, seconds."""
    poll_s: float = 0.01
    """How often a running move is checked, seconds."""

    def __post_init__(self) -> None:
        p = "devices.arm."
        try:
            super().__post_init__()
        except ValueError as exc:
            raise ValueError(f"{p}{exc}") from None
        require(
            isinstance(self.joint_names, list | tuple)
            and len(self.joint_names) > 0
            and all(isinstance(n, str) and n for n in self.joint_names),
            f"{p}joint_names: a list of joint names, got {self.joint_names!r}",
        )
        object.__setattr__(self, "joint_names", tuple(self.joint_names))
        for name in ("command_topic", "state_topic"):
            v = getattr(self, name)
            require(isinstance(v, str) and v.startswith("/"), f"{p}{name}: a ROS 2 topic name (/...), got {v!r}")
        for name in (
            "max_joint_speed_deg",
            "start_tolerance_deg",
            "goal_tolerance_deg",
            "path_tolerance_deg",
            "settle_s",
            "state_timeout_s",
            "timeout_margin_s",
            "poll_s",
        ):
            v = getattr(self, name)
            require(finite(v) and v > 0, f"{p}{name}: must be > 0, got {v!r}")

    @property
    def dds(self) -> DdsConfig:
        return DdsConfig(self.domain_id, self.interface, self.peers)


def joints_of(message: Any, names: tuple[str, ...]) -> NDArray[np.float64] | None:
    """(n,) the positions of ``names`` in a JointState, or None when one is missing."""
    index = {str(n): i for i, n in enumerate(message.name)}
    if any(n not in index or index[n] >= len(message.position) for n in names):
        return None
    return np.array([float(message.position[index[n]]) for n in names], dtype=np.float64)


def trajectory_message(trajectory: JointTrajectory) -> Any:
    """The ``trajectory_msgs/JointTrajectory`` of ``trajectory`` (header stamp 0: start now)."""
    from devices.drivers.ros2.messages import Duration, JointTrajectoryPoint, stamp_of
    from devices.drivers.ros2.messages import JointTrajectory as Message

    points = []
    for t, q, v in zip(trajectory.times, trajectory.positions, trajectory.velocities, strict=True):
        s = stamp_of(float(t))
        points.append(
            JointTrajectoryPoint(
                positions=[float(x) for x in q],
                velocities=[float(x) for x in v],
                time_from_start=Duration(sec=s.sec, nanosec=s.nanosec),
            )
        )
    return Message(joint_names=list(trajectory.joint_names), points=points)


class Ros2Arm:
    """A :class:`devices.protocols.JointArm` on ROS 2 topics (see the module docstring). DeviceError at start when
    no joint state with the configured joints arrives within ``state_timeout_s``."""

    def __init__(self, config: Ros2ArmConfig) -> None:
        from devices.drivers.ros2.messages import JointState
        from devices.drivers.ros2.messages import JointTrajectory as Message

        self.config = config
        self.last_joint_positions: NDArray[np.float64] | None = None
        self._last_stamp: float | None = None
        self._recorders: list[StampedSeries] = []
        self._stop = threading.Event()
        self._history: list[tuple[float, float, NDArray[np.float64]]] = []  # (arrival, stamp, q) while moving
        self._recording = False
        self._lock = threading.Lock()
        self._held = False
        self._subscriptions: list[Subscription] = []
        self.node = acquire(config.dds)
        self._held = True
        try:
            self.states = Subscription(self.node, config.state_topic, JointState, self._on_state)
            self._subscriptions.append(self.states)
            self.writer = self.node.writer(config.command_topic, Message)
            if self.states.wait(lambda m: joints_of(m, config.joint_names) is not None, config.state_timeout_s) is None:
                seen = "none arrived" if self.states.latest is None else f"they name {list(self.states.latest.name)}"
                raise DeviceError(
                    f"arm: no sensor_msgs/JointState with joints {list(config.joint_names)} on {config.state_topic} "
                    f"within {config.state_timeout_s:g} s ({seen}; DDS domain {config.domain_id})"
                )
        except BaseException:
            self.close()
            raise

    def _on_state(self, message: Any) -> None:
        from devices.drivers.ros2.messages import seconds_of

        q = joints_of(message, self.config.joint_names)
        if q is None:
            return
        stamp = seconds_of(message.header.stamp)
        with self._lock:
            self.last_joint_positions = q
            self._last_stamp = stamp
            recorders = list(self._recorders)
        for series in recorders:
            series.add(stamp, q)
        if self._recording:
            with self._lock:
                self._history.append((time.monotonic(), stamp, q))

    @property
    def joint_names(self) -> tuple[str, ...]:
        return self.config.joint_names

    def record_joints(self) -> StampedSeries:
        """A history of the joint states with their header stamps (ROS time, seconds), from the latest one on,
        until :meth:`stop_recording` (:class:`devices.movestream.JointRecorder`)."""
        series = StampedSeries()
        with self._lock:
            if self.last_joint_positions is not None and self._last_stamp is not None:
                series.add(self._last_stamp, self.last_joint_positions)
            self._recorders.append(series)
        return series

    def stop_recording(self, series: StampedSeries) -> None:
        with self._lock:
            if series in self._recorders:
                self._recorders.remove(series)

    def joint_positions(self) -> NDArray[np.float64]:
        """(n,) the latest joints, radians; DeviceError when the joint states are silent."""
        age = self.states.age()
        if self.last_joint_positions is None or age is None or age > self.config.state_timeout_s:
            raise DeviceError(
                f"arm: joint states silent: none on {self.config.state_topic} for "
                f"{'ever' if age is None else f'{age:.1f} s'} (limit {self.config.state_timeout_s:g} s)"
            )
        return self.last_joint_positions.copy()

    def _fault(self, reason: str, detail: str = "") -> ArmFaultError:
        self._send_stop()
        return ArmFaultError(reason, self.last_joint_positions, detail)

    def _send_stop(self) -> None:
        from devices.drivers.ros2.messages import JointTrajectory as Message

        with contextlib.suppress(Exception):
            self.writer.write(Message(joint_names=list(self.config.joint_names), points=[]))

    def execute(self, trajectory: JointTrajectory) -> None:
        """Send ``trajectory`` to the controller and block until the arm settled at its end (see the module
        docstring for the checks and the faults)."""
        c = self.config
        if tuple(trajectory.joint_names) != c.joint_names:
            raise DeviceError(f"arm: trajectory joints {list(trajectory.joint_names)} are not {list(c.joint_names)}")
        q0 = self.joint_positions()
        gap = float(np.max(np.abs(trajectory.start - q0)))
        if gap > math.radians(c.start_tolerance_deg):
            raise DeviceError(
                f"arm: the trajectory starts {math.degrees(gap):.2f} deg from the arm's joints "
                f"(at most {c.start_tolerance_deg:g})"
            )
        await_subscriber(
            self.writer,
            c.state_timeout_s,
            f"arm: no controller subscribes to {c.command_topic} (is the joint trajectory controller loaded and "
            "active?); nothing was sent",
        )
        self._stop.clear()
        dense = _dense(trajectory)
        end = trajectory.end
        goal = math.radians(c.goal_tolerance_deg)
        path = math.radians(c.path_tolerance_deg)
        limit = trajectory.duration * 1.5 + c.timeout_margin_s
        with self._lock:
            self._history = []
        self._recording = True
        try:
            self.writer.write(trajectory_message(trajectory))
            start = time.monotonic()
            checked = 0
            settled_since: float | None = None
            while True:
                if self._stop.is_set():
                    raise self._fault("stopped on request")
                now = time.monotonic()
                age = self.states.age()
                if age is None or age > c.state_timeout_s:
                    raise self._fault("joint states silent", f"none on {c.state_topic} for {age or 0:.1f} s")
                with self._lock:
                    fresh = self._history[checked:]
                    checked = len(self._history)
                for arrival, stamp, q in fresh:
                    t = arrival - start
                    reachable = dense[1] <= t + 0.5  # the path so far, with half a second of slack for latency
                    off = float(np.min(np.max(np.abs(dense[0][reachable] - q), axis=1)))
                    if off > path:
                        raise self._fault(
                            "deviation from the path",
                            f"{math.degrees(off):.2f} deg from the planned path at {t:.2f} s "
                            f"(at most {c.path_tolerance_deg:g})",
                        )
                    if float(np.max(np.abs(q - end))) <= goal:
                        if settled_since is None:
                            settled_since = arrival
                        elif arrival - settled_since >= c.settle_s:
                            self.node.settled_stamp = max(self.node.settled_stamp, stamp)
                            return
                    else:
                        settled_since = None
                if now - start > limit:
                    raise self._fault(
                        "too slow",
                        f"not at the goal {now - start:.1f} s after the start (the trajectory takes "
                        f"{trajectory.duration:.1f} s); did {c.command_topic} execute it?",
                    )
                time.sleep(c.poll_s)
        finally:
            self._recording = False

    def stop(self) -> None:
        """End a running move: the controller is told to hold, :meth:`execute` raises "stopped on request"."""
        self._stop.set()
        self._send_stop()

    def describe(self) -> str:
        q = self.joint_positions()
        rate = self.states.rate()
        return (
            f"ROS 2 arm {self.config.command_topic}: joints [{', '.join(f'{math.degrees(v):.1f}' for v in q)}] deg"
            + (f", {self.config.state_topic} at {rate:.0f} Hz" if rate else "")
        )

    def close(self) -> None:
        """Delete this device's readers, then release its share of the DDS participant (idempotent)."""
        for subscription in self._subscriptions:
            subscription.close()
        if self._held:
            self._held = False
            release(self.node)


def _dense(trajectory: JointTrajectory, dt: float = 0.02) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """((K, n) positions, (K,) times) of the trajectory sampled every ``dt`` seconds and at its points."""
    times = np.union1d(trajectory.times, np.arange(0.0, trajectory.duration, dt))
    positions = np.stack(
        [np.interp(times, trajectory.times, trajectory.positions[:, j]) for j in range(trajectory.positions.shape[1])],
        axis=1,
    )
    return positions, times
