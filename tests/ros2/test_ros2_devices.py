"""The ``ros2`` drivers and ``nbv devices check`` against the fake ROS 2 cell process (640x480 depth, over DDS on
loopback): what the check lists and what it says is missing, a full-size capture stamped after the devices settled,
and the arm's refusals and stop."""

from __future__ import annotations

import dataclasses
import math
import threading
import time
from collections.abc import Iterator
from pathlib import Path

import numpy as np
import pytest

from devices.cellfile import load_cell_file
from devices.config import CameraConfig, CellConfig
from devices.drivers.common import ArmFaultError
from devices.drivers.ros2.turntable import Ros2Turntable
from devices.hwcell import dry_run_cell
from devices.protocols import DeviceError
from devices.rig import open_device, open_rig
from devices.trajectory import JointTrajectory
from nbv.cli import main
from tests.ros2.fake_cell import TABLE_JTC
from tests.ros2.fakecell import FakeRos2Cell, cell_toml, fake_ros2_cell

VGA = CameraConfig(width=640, height=480, fx=610.0, fy=610.0, cx=319.5, cy=239.5, min_depth=0.05, max_depth=3.0)


@pytest.fixture(scope="module")
def cell(tmp_path_factory: pytest.TempPathFactory) -> Iterator[FakeRos2Cell]:
    with fake_ros2_cell(tmp_path_factory.mktemp("ros2dev"), camera=VGA, rate_hz=5.0) as fake:
        yield fake


def test_devices_check_lists_the_topics(cell: FakeRos2Cell, capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["devices", "check", "--cell", str(cell.path)]) == 0
    out = capsys.readouterr().out
    lines = out.strip().splitlines()
    assert lines[0].split()[:3] == ["camera", "ros2", "ok"] and "640x480" in lines[0] and "test capture" in lines[0]
    assert lines[1].split()[:3] == ["arm", "ros2", "ok"] and "-90.0" in lines[1]
    assert lines[2].split()[:3] == ["turntable", "ros2", "ok"] and "0.00 deg" in lines[2]
    assert lines[3] == "3 of 3 devices ok"
    assert lines[4] == f"ROS 2 topics (DDS domain {cell.domain}):"
    topics = {(line.split()[0], line.split()[1]): line for line in lines[5:-1]}
    depth = topics[("camera", "/camera/camera/depth/image_rect_raw")]
    assert "sensor_msgs/msg/Image" in depth and " ok " in depth and "640x480 16UC1" in depth
    rate = float(depth.split(" ok ")[1].split("Hz")[0])
    assert 2.0 < rate < 8.0  # the fake publishes at 5 Hz
    assert "fx 610.0" in topics[("camera", "/camera/camera/depth/camera_info")]
    assert "7 joints" in topics[("arm", "/joint_states")]
    command = topics[("arm", "/scaled_joint_trajectory_controller/joint_trajectory")]
    assert "trajectory_msgs/msg/JointTrajectory" in command and "1 subscriber" in command
    assert "std_msgs/msg/Float64" in topics[("turntable", "/turntable_controller/command")]
    assert lines[-1] == "6 of 6 topics ok"


def test_devices_check_says_what_is_missing(
    cell: FakeRos2Cell, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    wrong = tmp_path / "wrong.toml"
    text = cell_toml(
        cell.domain,
        camera='depth_topic = "/camera/depth/image_rect_raw"\ntimeout_s = 1.0',
        arm='command_topic = "/joint_trajectory_controller/joint_trajectory"\njoint_names = ["fr3_joint1", "fr3_joint2"]\nstate_timeout_s = 1.0',
    )
    wrong.write_text(text)
    assert main(["devices", "check", "--cell", str(wrong)]) == 1
    out = capsys.readouterr().out
    lines = out.strip().splitlines()
    # its camera info is there, its images are not
    assert lines[0].split()[:3] == ["camera", "ros2", "FAILED"]
    assert "no complete depth image on /camera/depth/image_rect_raw" in lines[0] and "none arrived" in lines[0]
    assert lines[1].split()[:3] == ["arm", "ros2", "FAILED"] and "fr3_joint1" in lines[1]
    missing = [line for line in lines if "MISSING" in line]
    assert any("/camera/depth/image_rect_raw" in line and "nothing received" in line for line in missing)
    assert any("/joint_states" in line and "joints ['fr3_joint1', 'fr3_joint2'] missing" in line for line in missing)
    assert any("/joint_trajectory_controller/joint_trajectory" in line and "no subscriber" in line for line in missing)
    assert lines[-1] == "3 of 6 topics ok; 3 missing"


@pytest.mark.slow
def test_a_640x480_capture_is_stamped_after_the_devices_settled(cell: FakeRos2Cell) -> None:
    from devices.drivers.ros2.messages import seconds_of

    cellfile = load_cell_file(cell.path)
    dry = dry_run_cell(cellfile, CellConfig(), None, VGA, seed=0)
    dry.move_to(dry.initial_pose())  # the first view's joints, from the same arm model
    q_view = dry.joint_positions()
    assert q_view is not None
    with open_rig(cellfile) as rig:
        camera, arm = rig.camera, rig.arm
        assert camera.intrinsics == VGA.intrinsics
        q0 = arm.joint_positions()
        times = np.linspace(0.0, 2.0, 21)
        path = q0 + (q_view - q0) * ((1 - np.cos(np.pi * times / 2.0)) / 2)[:, None]
        before = time.time()
        arm.execute(JointTrajectory(arm.joint_names, times, path, np.zeros_like(path)))
        settled = camera.node.settled_stamp  # the arm set it when it came to rest
        assert settled > before + 1.5
        frame = camera.capture()
        stamp = seconds_of(camera.depth.latest.header.stamp)
        assert stamp > settled
        assert frame.depth.shape == (480, 640) and frame.depth.dtype == np.float32
        assert frame.intrinsics == VGA.intrinsics
        valid = frame.depth[frame.depth > 0]
        assert valid.size > 20_000 and 0.3 < float(np.median(valid)) < 0.8  # the object and the plate, 0.55 m away
        # back home (in half the time: only where it ends matters), where the module's other tests expect the arm
        arm.execute(JointTrajectory(arm.joint_names, times / 2.0, path[::-1].copy(), np.zeros_like(path)))
        # a frame stamped a minute from now does not exist yet: no capture within the camera's timeout (a shorter
        # one than the cell file's 3 s: the same wait, less of it)
        camera.config = dataclasses.replace(camera.config, timeout_s=0.5)
        camera.node.settled_stamp = time.time() + 60.0
        with pytest.raises(DeviceError, match=r"no complete depth image .* stamped after the devices settled"):
            camera.capture()


def test_the_arm_refuses_a_far_start_and_stops_on_request(cell: FakeRos2Cell) -> None:
    spec = load_cell_file(cell.path).arm
    assert spec is not None
    arm = open_device(spec)
    try:
        q0 = arm.joint_positions()
        far = q0.copy()
        far[0] += math.radians(5.0)
        with pytest.raises(DeviceError, match=r"starts 5\.00 deg from the arm.s joints"):
            arm.execute(JointTrajectory(arm.joint_names, np.array([0.0, 1.0]), np.vstack([far, far]), np.zeros((2, 6))))
        assert np.allclose(arm.joint_positions(), q0, atol=1e-6)  # nothing was sent
        goal = q0.copy()
        goal[0] += math.radians(40.0)
        times = np.linspace(0.0, 4.0, 41)
        positions = q0 + (goal - q0) * ((1 - np.cos(np.pi * times / 4.0)) / 2)[:, None]
        trajectory = JointTrajectory(arm.joint_names, times, positions, np.zeros_like(positions))
        threading.Timer(1.0, arm.stop).start()
        with pytest.raises(ArmFaultError, match="stopped on request"):
            arm.execute(trajectory)
        time.sleep(0.3)
        held = arm.joint_positions()
        assert 0.01 < held[0] - q0[0] < math.radians(39.0)  # it had moved, and stopped short of the goal
        time.sleep(0.3)
        assert np.allclose(arm.joint_positions(), held, atol=1e-6)  # and holds there
        # back home, so the module's other tests find the arm where it started
        back = JointTrajectory(arm.joint_names, np.array([0.0, 1.0]), np.vstack([held, q0]), np.zeros((2, 6)))
        arm.execute(back)
        assert np.allclose(arm.joint_positions(), q0, atol=math.radians(0.5))
    finally:
        arm.close()


@pytest.mark.parametrize("command", ["float64", "trajectory"])
def test_the_turntable_turns_by_either_command(cell: FakeRos2Cell, command: str) -> None:
    spec = load_cell_file(cell.path).turntable
    assert spec is not None
    topic = spec.config.command_topic if command == "float64" else TABLE_JTC
    table = Ros2Turntable(dataclasses.replace(spec.config, command=command, command_topic=topic))
    try:
        start = table.angle
        began = time.monotonic()
        table.rotate_to(start + math.radians(45.0))
        took = time.monotonic() - began
        assert table.angle == pytest.approx(start + math.radians(45.0), abs=math.radians(0.2))
        assert took >= 45.0 / 180.0  # the fake turns at 180 deg/s
        assert table.node.settled_stamp > 0
        table.rotate_to(start)
        assert table.angle == pytest.approx(start, abs=math.radians(0.2))
    finally:
        table.close()
