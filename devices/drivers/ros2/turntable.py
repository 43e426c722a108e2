"""A turntable on ROS 2 topics: a one-joint controller, commanded by a ``std_msgs/Float64`` position (``command =
"float64"``) or a ``trajectory_msgs/JointTrajectory`` (``command = "trajectory"``, a joint trajectory controller
of one joint), its angle read from ``sensor_msgs/JointState``.

The plate angle is the joint's position (radians, counter-clockwise seen from above; ``invert`` flips it,
``zero_offset_deg`` is the plate angle at joint 0). A move is done when the joint is within ``tolerance_deg`` of
the target and stays there for ``settle_s`` (its stamp becomes the node's ``settled_stamp``); not there after
``|turn| / speed_deg + timeout_margin_s`` or silent joint states are a DeviceError. For move capture,
:meth:`Ros2Turntable.record_plate` keeps the plate angle of every joint state with its header stamp.
"""

from __future__ import annotations

import math
import threading
import time
from dataclasses import dataclass
from typing import Any

from devices.drivers.plate import check_angle
from devices.drivers.ros2.dds import DdsConfig, Subscription, acquire, await_subscriber, release
from devices.movestream import StampedSeries
from devices.protocols import DeviceError
from planner.validate import finite, require


@dataclass(frozen=True)
class Ros2TurntableConfig(DdsConfig):
    """``[devices.turntable] driver = "ros2"``."""

    joint_name: str = "turntable_joint"
    """The turntable's joint in the joint states."""
    command: str = "float64"
    """"float64" (a std_msgs/Float64 position command) or "trajectory" (a one-joint JointTrajectory)."""
    command_topic: str = "/turntable_controller/command"
    """Where the command goes."""
    state_topic: str = "/joint_states"
    """The ``sensor_msgs/JointState`` topic carrying the joint."""
    speed_deg: float = 30.0
    """The plate's speed, deg/s: the trajectory's timing, and how long a turn may take."""
    tolerance_deg: float = 0.2
    """A turn is done within this of the target, degrees."""
    settle_s: float = 0.2
    """The plate must stay within the tolerance this long, seconds."""
    state_timeout_s: float = 1.0
    """No joint state for this long is a fault, seconds."""
    timeout_margin_s: float = 5.0
    """A turn may take |turn| / speed_deg plus this, seconds."""
    invert: bool = False
    """The joint turns clockwise seen from above for positive positions."""
    zero_offset_deg: float = 0.0
    """The plate angle at joint position 0, degrees."""

    def __post_init__(self) -> None:
        p = "devices.turntable."
        try:
            super().__post_init__()
        except ValueError as exc:
            raise ValueError(f"{p}{exc}") from None
        require(isinstance(self.joint_name, str) and self.joint_name != "", f"{p}joint_name: required")
        require(
            self.command in ("float64", "trajectory"), f"{p}command: 'float64' or 'trajectory', got {self.command!r}"
        )
        for name in ("command_topic", "state_topic"):
            v = getattr(self, name)
            require(isinstance(v, str) and v.startswith("/"), f"{p}{name}: a ROS 2 topic name (/...), got {v!r}")
        for name in ("speed_deg", "tolerance_deg", "settle_s", "state_timeout_s", "timeout_margin_s"):
            v = getattr(self, name)
            require(finite(v) and v > 0, f"{p}{name}: must be > 0, got {v!r}")
        require(finite(self.zero_offset_deg), f"{p}zero_offset_deg: must be finite")

    @property
    def dds(self) -> DdsConfig:
        return DdsConfig(self.domain_id, self.interface, self.peers)


class Ros2Turntable:
    """A :class:`devices.protocols.Turntable` on ROS 2 topics (see the module docstring)."""

    def __init__(self, config: Ros2TurntableConfig) -> None:
        from devices.drivers.ros2.messages import Float64, JointState, JointTrajectory

        self.config = config
        self._stop = threading.Event()
        self._position: float | None = None
        self._stamp = 0.0
        self._recorders: list[StampedSeries] = []
        self._lock = threading.Lock()
        self._held = False
        self._subscriptions: list[Subscription] = []
        self.node = acquire(config.dds)
        self._held = True
        try:
            self.states = Subscription(self.node, config.state_topic, JointState, self._on_state)
            self._subscriptions.append(self.states)
            self.writer = self.node.writer(
                config.command_topic, Float64 if config.command == "float64" else JointTrajectory
            )
            if self.states.wait(lambda m: config.joint_name in m.name, config.state_timeout_s) is None:
                raise DeviceError(
                    f"turntable: no sensor_msgs/JointState with {config.joint_name!r} on {config.state_topic} within "
                    f"{config.state_timeout_s:g} s (DDS domain {config.domain_id})"
                )
        except BaseException:
            self.close()
            raise

    def _on_state(self, message: Any) -> None:
        from devices.drivers.ros2.messages import seconds_of

        names = list(message.name)
        if self.config.joint_name in names:
            i = names.index(self.config.joint_name)
            if i < len(message.position):
                position, stamp = float(message.position[i]), seconds_of(message.header.stamp)
                with self._lock:
                    self._position, self._stamp = position, stamp
                    recorders = list(self._recorders)
                for series in recorders:
                    series.add(stamp, self._plate(position))

    def record_plate(self) -> StampedSeries:
        """A history of the plate angle (radians) with the joint states' header stamps, from the latest one on,
        until :meth:`stop_recording` (:class:`devices.movestream.PlateRecorder`)."""
        series = StampedSeries()
        with self._lock:
            if self._position is not None:
                series.add(self._stamp, self._plate(self._position))
            self._recorders.append(series)
        return series

    def stop_recording(self, series: StampedSeries) -> None:
        with self._lock:
            if series in self._recorders:
                self._recorders.remove(series)

    def _plate(self, joint: float) -> float:
        sign = -1.0 if self.config.invert else 1.0
        return sign * joint + math.radians(self.config.zero_offset_deg)

    def _joint(self, plate: float) -> float:
        sign = -1.0 if self.config.invert else 1.0
        return sign * (plate - math.radians(self.config.zero_offset_deg))

    def _joint_now(self) -> float:
        age = self.states.age()
        if self._position is None or age is None or age > self.config.state_timeout_s:
            raise DeviceError(f"turntable: joint states silent: none on {self.config.state_topic} for {age or 0:.1f} s")
        return self._position

    @property
    def angle(self) -> float:
        """The plate angle, radians."""
        return self._plate(self._joint_now())

    def rotate_to(self, angle: float) -> None:
        """Turn the plate to ``angle`` (radians) and wait until it settled there."""
        from devices.drivers.ros2.messages import Duration, Float64, JointTrajectory, JointTrajectoryPoint, stamp_of

        angle = check_angle(angle)
        c = self.config
        start = self._joint_now()
        target = self._joint(angle)
        turn = abs(target - start)
        duration = max(math.degrees(turn) / c.speed_deg, 0.05)
        await_subscriber(
            self.writer,
            c.state_timeout_s,
            f"turntable: nothing subscribes to {c.command_topic} (is its controller loaded and active?); nothing was "
            "sent",
        )
        self._stop.clear()
        if c.command == "float64":
            self.writer.write(Float64(data=target))
        else:
            s = stamp_of(duration)
            self.writer.write(
                JointTrajectory(
                    joint_names=[c.joint_name],
                    points=[
                        JointTrajectoryPoint(
                            positions=[target], velocities=[0.0], time_from_start=Duration(s.sec, s.nanosec)
                        )
                    ],
                )
            )
        began = time.monotonic()
        limit = duration + c.timeout_margin_s
        tolerance = math.radians(c.tolerance_deg)
        since: float | None = None
        while True:
            if self._stop.is_set():
                raise DeviceError("turntable: stopped on request")
            q = self._joint_now()
            now = time.monotonic()
            if abs(q - target) <= tolerance:
                since = now if since is None else since
                if now - since >= c.settle_s:
                    self.node.settled_stamp = max(self.node.settled_stamp, self._stamp)
                    return
            else:
                since = None
            if now - began > limit:
                raise DeviceError(
                    f"turntable: not at {math.degrees(angle):.2f} deg {now - began:.1f} s after the command "
                    f"(at {math.degrees(self._plate(q)):.2f} deg); did {c.command_topic} execute it?"
                )
            time.sleep(0.01)

    def stop(self) -> None:
        """End a running turn: hold the plate where it is."""
        from devices.drivers.ros2.messages import Float64, JointTrajectory

        self._stop.set()
        if self._position is not None:
            if self.config.command == "float64":
                self.writer.write(Float64(data=self._position))
            else:
                self.writer.write(JointTrajectory(joint_names=[self.config.joint_name], points=[]))

    def describe(self) -> str:
        return f"ROS 2 turntable {self.config.joint_name}: plate at {math.degrees(self.angle):.2f} deg"

    def close(self) -> None:
        """Delete this device's readers, then release its share of the DDS participant (idempotent)."""
        for subscription in self._subscriptions:
            subscription.close()
        if self._held:
            self._held = False
            release(self.node)
