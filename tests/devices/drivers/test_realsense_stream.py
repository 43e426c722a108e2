"""Move capture from the RealSense driver's frame stream, on a recording written by librealsense's software device
with the stamps a live camera's global time domain gives (milliseconds since the epoch on the host clock): every
frame the streamer delivers is posed by the UR5's forward kinematics of the joints (and the plate angle)
interpolated at its stamp, carries its own image, and the frames that cannot be placed (stamped on the camera's
hardware clock, before the joint states) are dropped with their reason. The arm's history is hand-made here (a
UR arm is polled on the host clock during a real move: devices/movestream.py ``PolledSeries``)."""

from __future__ import annotations

import math
import time
from pathlib import Path

import numpy as np
import pytest

from devices.arm.kinematics import ArmKinematics
from devices.cellfile import T_table_base
from devices.config import ArmConfig
from devices.drivers.realsense import RealSenseCamera, RealSenseConfig
from devices.drivers.rsrecord import write_depth_recording
from devices.movestream import MoveStreamer, MoveStreamLimits, StampedSeries
from planner.types import DepthFrame, Pose
from tests.devices.drivers.rsfixtures import DEPTH_UNIT, SMALL

FPS = 30
MOVE_S = 0.8


def joints_at(t: float) -> np.ndarray:
    """A smooth UR5 move from its usual scanning pose, radians."""
    q0 = np.radians([0.0, -90.0, 90.0, -90.0, -90.0, 0.0])
    dq = np.radians([30.0, -15.0, 20.0, 10.0, 0.0, 45.0])
    s = (1 - math.cos(math.pi * min(max(t, 0.0), MOVE_S) / MOVE_S)) / 2
    return q0 + s * dq


def test_frames_from_the_realsense_stream_are_posed_at_their_global_time_stamps(tmp_path: Path) -> None:
    t0 = time.time() - 100.0  # the move started 100 s ago, on the host clock
    frame_t = [0.004 + i / FPS for i in range(int(MOVE_S * FPS))]
    stamps_ms = [(t0 - 10.0) * 1000.0] + [(t0 + t) * 1000.0 for t in frame_t]
    domains = ["global_time"] * len(stamps_ms)
    domains[10] = "hardware_clock"  # a frame the camera stamped on its own clock
    depths = [np.full((SMALL.height, SMALL.width), 0.3 + 0.01 * i, dtype=np.float32) for i in range(len(stamps_ms))]
    k = SMALL.intrinsics
    path = write_depth_recording(
        tmp_path / "move.db3", depths, k, depth_unit=DEPTH_UNIT, fps=FPS, timestamps_ms=stamps_ms, domains=domains
    )

    kinematics = ArmKinematics(ArmConfig(), plate_radius=0.2, plate_thickness=0.02)
    joints, plate = StampedSeries(), StampedSeries()
    for t in np.arange(0.0, MOVE_S + 0.05, 0.008):  # a UR's 125 Hz
        joints.add(t0 + t, joints_at(t))
        plate.add(t0 + t, 0.3 * t)

    def pose_of(q: np.ndarray, theta: float) -> Pose:
        return T_table_base(theta) @ kinematics.camera_pose(q)

    got: list[tuple[DepthFrame, float]] = []
    config = RealSenseConfig(width=80, height=60, fps=FPS, playback=str(path), min_depth=0.05, timeout_s=1.0)
    with RealSenseCamera(config) as camera:
        streamer = MoveStreamer(
            camera.stream(),
            joints,
            plate,
            pose_of,
            t0,
            10.0,
            lambda frame, t: got.append((frame, t)),
            MoveStreamLimits(wait_s=0.5),
        )
        deadline = time.monotonic() + 10.0
        while streamer.stats.received < len(stamps_ms) and time.monotonic() < deadline:
            time.sleep(0.02)
        stats = streamer.finish(t0 + MOVE_S)
    assert stats.received == len(stamps_ms)
    assert stats.dropped == {"before_history": 1, "clock": 1}, stats.summary()
    assert stats.placed == len(frame_t) - 1 and stats.failed == 0 and stats.error == ""
    ticks = np.arange(1, math.ceil(MOVE_S * 10)) / 10.0  # strictly inside the move
    assert stats.delivered == len(got) == len(ticks)
    placed_t = np.array([t for i, t in enumerate(frame_t) if i + 1 != 10])
    for (frame, t), tick in zip(got, ticks, strict=True):
        assert t == pytest.approx(placed_t[np.argmin(np.abs(placed_t - tick))], abs=1e-6)  # nearest its tick
        i = frame_t.index(min(frame_t, key=lambda v: abs(v - t))) + 1
        valid = frame.depth > 0
        assert valid.all() and np.allclose(frame.depth, depths[i], atol=DEPTH_UNIT)  # its own image
        # the joints between the two UR states around the stamp, interpolated
        s0 = math.floor(t / 0.008) * 0.008
        w = (t - s0) / 0.008
        q = (1 - w) * joints_at(s0) + w * joints_at(s0 + 0.008)
        want = pose_of(q, 0.3 * t)
        assert np.max(np.abs(frame.T_world_camera.matrix - want.matrix)) < 1e-6
        assert frame.intrinsics == k


def test_a_hardware_cell_places_the_realsense_frames_of_a_ur_move_by_its_polled_joints(tmp_path: Path) -> None:
    """The whole path on one cell file: RealSense (a recording stamped on the host clock over the next seconds,
    read ahead: each frame waits until the arm's readings pass its stamp), the fake UR read 200 times a second, the
    fake GRBL's status reports. Each delivered pose against the fake controller's true joints at the frame's stamp."""
    from devices.cellfile import load_cell_file
    from devices.config import CellConfig
    from devices.hwcell import configured_arm, hardware_cell
    from devices.motion import Motion
    from devices.move_capture import MoveFrame
    from devices.rig import open_rig
    from devices.trajectory import JointTrajectory
    from tests.devices.drivers.rigfixtures import cell_toml, fake_hardware_cell

    arm_speed = "max_joint_speed_deg = 60"
    # The arm model is built once per process (about 1 s, measured over 2.5 s on a loaded machine): built here,
    # before the recording is stamped, so the cell opens well within the recording's lead.
    warm = tmp_path / "arm.toml"
    warm.write_text(cell_toml("/dev/null", SMALL.intrinsics, arm_speed=arm_speed))
    configured_arm(load_cell_file(warm), CellConfig())
    # Frames at 20 fps (two per tick of the 10 Hz capture, so each tick inside the move has a frame of its own) over
    # three seconds from 0.3 s on: the move starts once the cell is open and the recording must still cover it; all
    # 60 frames fit the streamer's queue of 64.
    start = time.time() + 0.3
    stamps_ms = [(start + i / 20.0) * 1000.0 for i in range(60)]
    depths = [np.full((SMALL.height, SMALL.width), 0.5, dtype=np.float32)] * len(stamps_ms)
    with fake_hardware_cell(
        tmp_path,
        depths,
        SMALL.intrinsics,
        arm_speed=arm_speed,
        camera="move_capture_wait_s = 3.0\nmove_capture_gap_s = 0.3",  # room for a loaded machine's scheduling
        timestamps_ms=stamps_ms,
        domains=["global_time"] * len(stamps_ms),
    ) as fake:
        cellfile = load_cell_file(fake.path)
        with open_rig(cellfile) as rig:
            hw = hardware_cell(rig)
            assert hw.kinematics is not None
            q0 = hw.joint_positions()
            assert q0 is not None
            q1 = q0 + np.radians([10.0, -5.0, 5.0, 5.0, 0.0, 10.0])
            times = np.array([0.0, 0.5])
            trajectory = JointTrajectory(hw.arm.joint_names, times, np.vstack([q0, q1]), np.zeros((2, 6)))
            motion = Motion(hw.angle, hw.kinematics.camera_pose(q1), q=q1, trajectory=trajectory, duration=0.5)
            got: list[MoveFrame] = []
            offset = time.time() - time.monotonic()
            while time.time() < start + 0.1:
                time.sleep(0.01)
            hw.move_to(motion.T_base_camera, motion=motion, capture_hz=10.0, on_frame=got.append)
            stats = hw.last_move_stream
            # the controller's path (monotonic clock), read after the move: a frame may be delivered before the
            # path starts (the arm still at q0) or after it ended (the controller then forgets its segments)
            assert len(fake.controller.paths) == 1
            segments = fake.controller.paths[0]
    assert stats is not None and stats.t0 is not None and stats.end is not None, stats
    assert stats.error == "" and stats.failed == 0 and set(stats.dropped) <= {"before_history"}, stats.summary()
    moved = stats.end - stats.t0
    assert stats.end < stamps_ms[-1] / 1000.0 - 0.1  # the recording covers the move
    assert stats.delivered == len(got) == math.ceil(moved * 10.0) - 1 >= 4, stats.summary()
    errors = []
    for frame in got:
        t = stats.t0 + frame.t - offset  # the stamp on the controller's (monotonic) clock
        q = segments[-1][3]
        for a, b, qa, qb in segments:  # the first one has no length (from the joints the arm is at)
            if t <= b:  # a frame stamped before the path started: the arm still at the path's first joints
                q = qa if b == a else qa + min(max((t - a) / (b - a), 0.0), 1.0) * (qb - qa)
                break
        true = T_table_base(0.0) @ hw.kinematics.camera_pose(q)
        errors.append(float(np.linalg.norm(frame.frame.T_world_camera.translation - true.translation)))
    assert max(errors) < 0.002, errors  # the polling's 5 ms at the camera's speed, and the two clocks' offset
    print(
        f"\nRealSense + UR + GRBL, {stats.summary()}; position error vs the true joints max {max(errors) * 1000:.2f} mm"
    )
