"""A ROS 2 cell in a separate process, for the tests: camera, arm and turntable as ROS 2 nodes would publish them.

``python -m tests.ros2.fake_cell CELL_TOML CAMERA_JSON`` reads the cell file's ``ros2`` sections (topics, DDS
domain, interface, peers) and publishes over DDS, like ``realsense2_camera`` and a ros2_control driver:

- ``sensor_msgs/JointState`` on the arm's state topic at 100 Hz (the arm's joints and the turntable's joint);
- ``sensor_msgs/Image`` (16UC1, mm) + ``sensor_msgs/CameraInfo`` at ``rate_hz``, rendered by our simulated camera
  (CAMERA_JSON: a :class:`devices.config.CameraConfig`'s fields, plus ``model``, ``size``) at the pose forward
  kinematics of the current joints (the cell file's arm model and hand-eye) and the plate angle give;
- executes a ``trajectory_msgs/JointTrajectory`` in real time as a joint trajectory controller does (an empty one:
  hold where it is), and turns the plate at ``turntable_speed_deg`` deg/s to a ``std_msgs/Float64`` position (the
  cell file's command topic) or to the last point of a one-joint ``JointTrajectory`` on ``TABLE_JTC``.

It prints ``ready`` once publishing. Faults are lines on stdin, each answered by ``ok``: ``silent_camera``,
``ignore_trajectory``, ``jump`` (joints jump 20 degrees in the middle of the next move), ``encoding rgb8``,
``silent_joints``, ``pause_joints S`` (no joint state for S seconds from now, the joints moving on meanwhile),
``stale_frame`` (the next depth image is stamped 30 s in the past), ``reset``.
"""

from __future__ import annotations

import json
import math
import sys
import threading
import time
from typing import Any

import numpy as np

TABLE_JTC = "/turntable_controller/joint_trajectory"
"""The turntable also follows a one-joint JointTrajectory here (a ros2_control joint trajectory controller)."""


def main(argv: list[str]) -> int:
    from devices.builtins import resolve_model
    from devices.cellfile import T_table_base, load_cell_file
    from devices.config import CameraConfig, CellConfig
    from devices.drivers.ros2.dds import Subscription, acquire, command_qos
    from devices.drivers.ros2.messages import (
        CameraInfo,
        Float64,
        Header,
        Image,
        JointState,
        JointTrajectory,
        RegionOfInterest,
        seconds_of,
        stamp_of,
    )
    from devices.hwcell import configured_arm
    from devices.sim import SimulatedCamera

    cell = load_cell_file(argv[0])
    spec = json.loads(argv[1])
    rate_hz = float(spec.pop("rate_hz", 15.0))
    model = spec.pop("model", "l-block")
    size = float(spec.pop("size", 0.2))
    turntable_speed = math.radians(float(spec.pop("turntable_speed_deg", 90.0)))
    camera_config = CameraConfig(**spec)
    assert cell.camera is not None and cell.arm is not None and cell.turntable is not None
    cam_cfg, arm_cfg, table_cfg = cell.camera.config, cell.arm.config, cell.turntable.config
    config, kinematics = configured_arm(cell, CellConfig())
    node = acquire(cam_cfg.dds)

    lock = threading.Lock()
    state: dict[str, Any] = {
        "q": np.array([0.0, -1.57, 1.57, -1.57, -1.57, 0.0]),
        "theta_joint": 0.0,
        "table_target": 0.0,
        "trajectory": None,  # (start, times (K,), positions (K, n))
        "faults": set(),
        "encoding": "16UC1",
        "paused_until": 0.0,
    }

    def joint_now() -> tuple[np.ndarray, float]:
        with lock:
            return state["q"].copy(), float(state["theta_joint"])

    def plate(joint: float) -> float:
        sign = -1.0 if table_cfg.invert else 1.0
        return sign * joint + math.radians(table_cfg.zero_offset_deg)

    _, mesh = resolve_model(model, size=size)

    def pose() -> Any:
        q, joint = joint_now()
        return T_table_base(plate(joint), cell.turntable_axis) @ kinematics.camera_pose(q)

    camera = SimulatedCamera(mesh, camera_config, plate_radius=config.plate_radius, pose_source=pose)

    def on_trajectory(message: Any) -> None:
        with lock:
            if "ignore_trajectory" in state["faults"]:
                return
            if list(message.joint_names) != list(arm_cfg.joint_names) or not message.points:
                state["trajectory"] = None  # an empty trajectory: hold here
                return
            times = np.array([seconds_of(p.time_from_start) for p in message.points])
            positions = np.array([list(p.positions) for p in message.points])
            if times[0] > 0:  # the controller starts from where the arm is
                times = np.concatenate([[0.0], times])
                positions = np.vstack([state["q"], positions])
            state["trajectory"] = (time.monotonic(), times, positions)

    def on_table(message: Any) -> None:
        with lock:
            state["table_target"] = float(message.data)

    def on_table_trajectory(message: Any) -> None:
        with lock:
            if list(message.joint_names) != [table_cfg.joint_name]:
                return
            if message.points:
                state["table_target"] = float(message.points[-1].positions[0])
            else:  # an empty trajectory: hold here
                state["table_target"] = state["theta_joint"]

    _traj = Subscription(node, arm_cfg.command_topic, JointTrajectory, on_trajectory, qos=command_qos())
    _table = Subscription(node, table_cfg.command_topic, Float64, on_table, qos=command_qos())
    _table_jtc = Subscription(node, TABLE_JTC, JointTrajectory, on_table_trajectory, qos=command_qos())
    joints_writer = node.sensor_writer(arm_cfg.state_topic, JointState)
    image_writer = node.sensor_writer(cam_cfg.depth_topic, Image)
    info_writer = node.sensor_writer(cam_cfg.info_topic, CameraInfo)
    stop = threading.Event()

    def joints_loop() -> None:
        names = [*arm_cfg.joint_names, table_cfg.joint_name]
        while not stop.is_set():
            now = time.monotonic()
            with lock:
                traj = state["trajectory"]
                if traj is not None:
                    start, times, positions = traj
                    t = now - start
                    q = np.array([np.interp(t, times, positions[:, j]) for j in range(positions.shape[1])])
                    if "jump" in state["faults"] and t > times[-1] / 2:
                        q[0] += math.radians(20.0)
                        state["faults"].discard("jump")
                        state["trajectory"] = None
                    elif t >= times[-1]:
                        state["trajectory"] = None
                    state["q"] = q
                step = turntable_speed * 0.01
                gap = state["table_target"] - state["theta_joint"]
                state["theta_joint"] += max(-step, min(step, gap))
                q, joint = state["q"].copy(), state["theta_joint"]
                silent = "silent_joints" in state["faults"] or now < state["paused_until"]
            if not silent:
                joints_writer.write(
                    JointState(
                        header=Header(stamp=stamp_of(time.time())),
                        name=names,
                        position=[*(float(v) for v in q), joint],
                        velocity=[0.0] * len(names),
                        effort=[],
                    )
                )
            time.sleep(0.01)

    def camera_loop() -> None:
        k = camera_config.intrinsics
        while not stop.is_set():
            began = time.monotonic()
            stamp = stamp_of(time.time())
            frame = camera.capture()
            header = Header(stamp=stamp, frame_id="camera_depth_optical_frame")
            info = CameraInfo(
                header=header,
                height=k.height,
                width=k.width,
                distortion_model="plumb_bob",
                d=[0.0] * 5,
                k=[k.fx, 0.0, k.cx, 0.0, k.fy, k.cy, 0.0, 0.0, 1.0],
                r=[1.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 1.0],
                p=[k.fx, 0.0, k.cx, 0.0, 0.0, k.fy, k.cy, 0.0, 0.0, 0.0, 1.0, 0.0],
                roi=RegionOfInterest(),
            )
            with lock:
                silent = "silent_camera" in state["faults"]
                encoding = state["encoding"]
                if "stale_frame" in state["faults"]:
                    state["faults"].discard("stale_frame")
                    header = Header(stamp=stamp_of(time.time() - 30.0), frame_id=header.frame_id)
            info_writer.write(info)
            if not silent:
                mm = np.round(frame.depth * 1000.0).astype("<u2")
                image = Image(
                    header=header, height=k.height, width=k.width, encoding=encoding, step=k.width * 2, data=mm
                )
                image_writer.write(image)
            time.sleep(max(0.0, 1.0 / rate_hz - (time.monotonic() - began)))

    threads = [threading.Thread(target=f, daemon=True) for f in (joints_loop, camera_loop)]
    for t in threads:
        t.start()
    print("ready", flush=True)
    for line in sys.stdin:
        words = line.split()
        if not words:
            continue
        with lock:
            if words[0] == "reset":
                state["faults"].clear()
                state["encoding"] = "16UC1"
                state["paused_until"] = 0.0
            elif words[0] == "encoding":
                state["encoding"] = words[1]
            elif words[0] == "pause_joints":
                state["paused_until"] = time.monotonic() + float(words[1])
            else:
                state["faults"].add(words[0])
        print("ok", flush=True)
    stop.set()
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
