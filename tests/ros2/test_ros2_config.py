"""The ``ros2`` sections of a cell file: defaults that match realsense2_camera and ur_robot_driver, one-line errors
naming the field, the DDS configuration they make, and one network set-up per domain in a process."""

from __future__ import annotations

from pathlib import Path

import pytest

from devices.cellfile import load_cell_file
from devices.drivers.ros2 import DdsConfig, Ros2ArmConfig, Ros2CameraConfig, Ros2TurntableConfig
from devices.drivers.ros2.dds import acquire, release, ros_topic
from devices.protocols import DeviceError


def test_defaults_are_the_ros_drivers_topics() -> None:
    camera, arm, table = Ros2CameraConfig(), Ros2ArmConfig(), Ros2TurntableConfig()
    assert camera.depth_topic == "/camera/camera/depth/image_rect_raw"
    assert camera.info_topic == "/camera/camera/depth/camera_info"
    assert arm.command_topic == "/scaled_joint_trajectory_controller/joint_trajectory"
    assert arm.state_topic == "/joint_states" and arm.joint_names[0] == "shoulder_pan_joint"
    assert table.command == "float64" and camera.domain_id == arm.domain_id == table.domain_id == 0
    assert ros_topic("/joint_states") == "rt/joint_states"


def test_the_cell_file_reads_the_ros2_sections(tmp_path: Path) -> None:
    path = tmp_path / "cell.toml"
    path.write_text(
        '[devices.camera]\ndriver = "ros2"\ndomain_id = 7\ninterface = "eth1"\npeers = ["10.0.0.2"]\n'
        'depth_topic = "/d435/depth/image_rect_raw"\n'
        '[devices.arm]\ndriver = "ros2"\ndomain_id = 7\njoint_names = ["fr3_joint1", "fr3_joint2"]\n'
        'command_topic = "/fr3_arm_controller/joint_trajectory"\n'
        '[devices.turntable]\ndriver = "ros2"\ncommand = "trajectory"\ninvert = true\n'
    )
    cell = load_cell_file(path)
    assert cell.camera is not None and cell.arm is not None and cell.turntable is not None
    camera, arm, table = cell.camera.config, cell.arm.config, cell.turntable.config
    assert camera.dds == DdsConfig(7, "eth1", ("10.0.0.2",)) and camera.depth_topic == "/d435/depth/image_rect_raw"
    assert arm.joint_names == ("fr3_joint1", "fr3_joint2") and arm.dds == DdsConfig(7)
    assert table.command == "trajectory" and table.invert is True


@pytest.mark.parametrize(
    ("section", "text", "message"),
    [
        ("camera", "domain_id = 300", r"^devices\.camera\.domain_id: an integer in \[0, 232\]"),
        ("camera", 'depth_topic = "camera/depth"', r"^devices\.camera\.depth_topic: a ROS 2 topic name"),
        ("camera", "timeout_s = 0", r"^devices\.camera\.timeout_s: must be > 0"),
        ("camera", 'noise_model = "kinect"', r"^devices\.camera\.noise_model: one of"),
        ("arm", "joint_names = []", r"^devices\.arm\.joint_names: a list of joint names"),
        ("arm", "path_tolerance_deg = -1", r"^devices\.arm\.path_tolerance_deg: must be > 0"),
        ("arm", "peers = [1]", r"^devices\.arm\.peers: a list of addresses"),
        ("turntable", 'command = "velocity"', r"^devices\.turntable\.command: 'float64' or 'trajectory'"),
        ("turntable", "colour = 3", r"^devices\.turntable\.colour: unknown setting"),
    ],
)
def test_bad_values_are_one_line_naming_the_field(tmp_path: Path, section: str, text: str, message: str) -> None:
    path = tmp_path / "cell.toml"
    path.write_text(f'[devices.{section}]\ndriver = "ros2"\n{text}\n')
    with pytest.raises(ValueError, match=message) as info:
        load_cell_file(path)
    assert "\n" not in str(info.value)


def test_the_network_settings_make_a_cyclonedds_configuration() -> None:
    assert DdsConfig().xml() == ""
    xml = DdsConfig(3, "lo", ("127.0.0.1",)).xml()
    assert '<NetworkInterface name="lo"/>' in xml and "<AllowMulticast>false</AllowMulticast>" in xml
    assert '<Peer address="127.0.0.1"/>' in xml


def test_one_network_set_up_per_domain_in_a_process() -> None:
    domain = 1 + (hash("one set-up") % 200)
    node = acquire(DdsConfig(domain, "lo", ("127.0.0.1",)))
    try:
        assert acquire(DdsConfig(domain, "lo", ("127.0.0.1",))) is node  # shared
        release(node)
        with pytest.raises(DeviceError, match=f"DDS domain {domain}: already open with interface 'lo'"):
            acquire(DdsConfig(domain, "eth9"))
    finally:
        release(node)
