"""What ``nbv devices check`` says about a ``ros2`` cell's topics: each topic the cell file names, whether it is
there, its type, its rate, and what is missing.

Every topic the devices read (images, camera info, joint states) is subscribed with its ROS 2 type for
``listen_s`` seconds: its rate and the last message's content (an image's encoding and size, the joint names); a
topic nothing arrives on is missing (no publisher, a publisher of another type, another domain or network). A
command topic (a controller's) is there when a subscriber matches our writer (nothing is sent on it).
"""

from __future__ import annotations

import time
from dataclasses import dataclass
from typing import Any

from devices.cellfile import CellFile
from devices.drivers.ros2.dds import Subscription, acquire, release


@dataclass(frozen=True)
class TopicCheck:
    """One topic of the cell file: who uses it, its ROS 2 type, whether it is there and what was seen."""

    device: str
    topic: str
    ros_type: str
    ok: bool
    message: str

    def line(self) -> str:
        state = "ok" if self.ok else "MISSING"
        return f"  {self.device:<10s} {self.topic:<52s} {self.ros_type:<36s} {state:<8s}{self.message}"


def _content(message: Any, joints: tuple[str, ...]) -> tuple[bool, str]:
    """(usable, a short description) of the last message of a topic."""
    from devices.drivers.ros2.camera import DEPTH_ENCODINGS
    from devices.drivers.ros2.messages import CameraInfo, Image, JointState

    if isinstance(message, Image):
        ok = str(message.encoding) in DEPTH_ENCODINGS
        note = "" if ok else f" (not a depth encoding: one of {', '.join(DEPTH_ENCODINGS)})"
        return ok, f"{message.width}x{message.height} {message.encoding}{note}"
    if isinstance(message, CameraInfo):
        k = list(message.k)
        return True, f"{message.width}x{message.height}, fx {k[0]:.1f} fy {k[4]:.1f} cx {k[2]:.1f} cy {k[5]:.1f}"
    if isinstance(message, JointState):
        names = [str(n) for n in message.name]
        missing = [n for n in joints if n not in names]
        if missing:
            return False, f"joints {missing} missing (it names {names})"
        return True, f"{len(names)} joints"
    return True, ""


def topic_report(cell: CellFile, listen_s: float = 1.5) -> list[TopicCheck]:
    """One :class:`TopicCheck` per topic of the cell file's ``ros2`` devices (see the module docstring)."""
    from devices.drivers.ros2.messages import (
        ROS_TYPE_NAMES,
        CameraInfo,
        Float64,
        Image,
        JointState,
        JointTrajectory,
    )

    reads: list[tuple[str, str, type, tuple[str, ...]]] = []  # (device, topic, type, joints it must carry)
    commands: list[tuple[str, str, type]] = []
    specs = [s for s in cell.devices() if s.driver == "ros2"]
    if not specs:
        return []
    for spec in specs:
        c = spec.config
        if spec.kind == "camera":
            reads += [("camera", c.depth_topic, Image, ()), ("camera", c.info_topic, CameraInfo, ())]
        elif spec.kind == "arm":
            reads.append(("arm", c.state_topic, JointState, c.joint_names))
            commands.append(("arm", c.command_topic, JointTrajectory))
        else:
            reads.append(("turntable", c.state_topic, JointState, (c.joint_name,)))
            commands.append(("turntable", c.command_topic, Float64 if c.command == "float64" else JointTrajectory))
    node = acquire(specs[0].config.dds)
    subscriptions: dict[str, Subscription] = {}
    try:
        for _, topic, message, _ in reads:
            if topic not in subscriptions:
                subscriptions[topic] = Subscription(node, topic, message)
        writers = {topic: node.writer(topic, message) for _, topic, message in commands}
        time.sleep(listen_s)
        report = []
        for device, topic, message, joints in reads:
            sub = subscriptions[topic]
            ros_type = ROS_TYPE_NAMES[message.__name__]
            if sub.latest is None:
                report.append(
                    TopicCheck(
                        device,
                        topic,
                        ros_type,
                        False,
                        f"nothing received in {listen_s:g} s (no publisher, another type, or another domain/network)",
                    )
                )
                continue
            ok, what = _content(sub.latest, joints)
            rate = sub.rate()
            rate_text = f"{rate:.1f} Hz" if rate is not None else f"{sub.count} message"
            report.append(TopicCheck(device, topic, ros_type, ok, f"{rate_text}, {what}" if what else rate_text))
        for device, topic, message in commands:
            n = len(writers[topic].get_matched_subscriptions())
            ros_type = ROS_TYPE_NAMES[message.__name__]
            if n:
                report.append(TopicCheck(device, topic, ros_type, True, f"{n} subscriber{'s' if n > 1 else ''}"))
            else:
                report.append(
                    TopicCheck(device, topic, ros_type, False, "no subscriber (is the controller loaded and active?)")
                )
        return report
    finally:
        for sub in subscriptions.values():
            sub.close()
        release(node)
