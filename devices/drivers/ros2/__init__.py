"""The ``ros2`` cell: camera, arm and turntable drivers speaking plain ROS 2 topics over DDS (extra ``[ros2]``).

No ROS install is needed: ``cyclonedds`` (PyPI) publishes and subscribes ROS 2 topics (``rt/<name>``, the ROS 2
message types of :mod:`devices.drivers.ros2.messages`). The configs here import nothing from ``cyclonedds``;
opening a device does (a missing package is one error naming the extra). See ``docs/ros2.md``.
"""

from devices.drivers.ros2.arm import Ros2ArmConfig
from devices.drivers.ros2.camera import Ros2CameraConfig
from devices.drivers.ros2.dds import DdsConfig
from devices.drivers.ros2.turntable import Ros2TurntableConfig

__all__ = ["DdsConfig", "Ros2ArmConfig", "Ros2CameraConfig", "Ros2TurntableConfig"]
