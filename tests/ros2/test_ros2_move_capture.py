"""Capture during a move on the ``ros2`` cell, over DDS on loopback against the fake ROS 2 cell process: joint states
at 100 Hz, depth images at 30 Hz, both stamped. Every frame ``HardwareCell.move_to(capture_hz, on_frame)`` delivers
is posed by forward kinematics of the joints (and the plate angle) interpolated at its stamp, checked against the
test's own subscription to the joint states; one frame per rate tick inside the move; frames that cannot be placed
(a stamp outside the joint-state history, a gap in the joint states) are dropped with their reason; a failing
consumer does not break the move; a halt ends the stream."""

from __future__ import annotations

import math
import threading
import time
from collections.abc import Iterator
from typing import Any

import numpy as np
import pytest

from devices.cellfile import T_table_base, load_cell_file
from devices.drivers.ros2.arm import joints_of
from devices.drivers.ros2.dds import Subscription
from devices.hwcell import HardwareCell, hardware_cell
from devices.motion import Motion
from devices.move_capture import MoveFrame, capture_times
from devices.protocols import DeviceError
from devices.rig import open_rig
from devices.trajectory import JointTrajectory
from tests.ros2.fakecell import FakeRos2Cell, fake_ros2_cell

pytestmark = pytest.mark.slow

CAMERA_HZ = 30.0


@pytest.fixture(scope="module")
def cell(tmp_path_factory: pytest.TempPathFactory) -> Iterator[FakeRos2Cell]:
    # a gap limit with room for a loaded machine's scheduling (the fake publishes every 10 ms)
    with fake_ros2_cell(
        tmp_path_factory.mktemp("ros2move"), rate_hz=CAMERA_HZ, camera_section="move_capture_gap_s = 0.2"
    ) as fake:
        yield fake


class States:
    """The test's own record of the joint states: (stamp, arm joints, plate joint) of each message."""

    def __init__(self, hw: HardwareCell) -> None:
        from devices.drivers.ros2.messages import JointState, seconds_of

        self.rows: list[tuple[float, np.ndarray, float]] = []
        names = tuple(hw.arm.joint_names)

        def on_state(message: Any) -> None:
            q = joints_of(message, names)
            plate = joints_of(message, ("turntable_joint",))
            if q is not None and plate is not None:
                self.rows.append((seconds_of(message.header.stamp), q, float(plate[0])))

        self.subscription = Subscription(hw.arm.node, "/joint_states", JointState, on_state)

    def at(self, stamp: float) -> tuple[np.ndarray, float, float, bool]:
        """(joints, plate angle, gap between the bracketing states, whether they differ) interpolated at
        ``stamp``."""
        rows = sorted(self.rows, key=lambda r: r[0])
        stamps = np.array([r[0] for r in rows])
        i = int(np.searchsorted(stamps, stamp))
        assert 0 < i < len(rows), f"stamp {stamp} outside the test's record"
        (s0, q0, p0), (s1, q1, p1) = rows[i - 1], rows[i]
        w = (stamp - s0) / (s1 - s0)
        moving = not (np.array_equal(q0, q1) and p0 == p1)
        return q0 + w * (q1 - q0), p0 + w * (p1 - p0), s1 - s0, moving


class Images:
    """The test's own record of the depth images' header stamps."""

    def __init__(self, hw: HardwareCell) -> None:
        from devices.drivers.ros2.messages import Image, seconds_of

        self.stamps: list[float] = []
        self.subscription = Subscription(
            hw.arm.node,
            "/camera/camera/depth/image_rect_raw",
            Image,
            lambda m: self.stamps.append(seconds_of(m.header.stamp)),
        )

    def nearest(self, t0: float, end: float, ticks: np.ndarray) -> list[float]:
        """The stamps (s since t0) the rate should pick: for each tick the nearer of the frames just before and
        after it (after the last frame: the last one, when within a period of the tick), each once."""
        frames = sorted(s - t0 for s in self.stamps if t0 <= s <= end)
        period = float(ticks[1] - ticks[0]) if len(ticks) > 1 else 1.0
        picked: list[float] = []
        for tick in ticks:
            before = [f for f in frames if f <= tick]
            after = [f for f in frames if f >= tick]
            if after:
                choice = before[-1] if before and tick - before[-1] <= after[0] - tick else after[0]
            elif before and tick - before[-1] <= period:
                choice = before[-1]
            else:
                continue
            if not picked or choice > picked[-1]:
                picked.append(choice)
        return picked


def move(hw: HardwareCell, offsets_deg: list[float], turn_deg: float, seconds: float) -> Motion:
    """A motion from where the arm is: the joints by ``offsets_deg`` in ``seconds`` (smooth), the plate turning
    ``turn_deg`` at the same time."""
    q0 = hw.joint_positions()
    assert q0 is not None
    q1 = q0 + np.radians(offsets_deg)
    times = np.linspace(0.0, seconds, 21)
    s = (1 - np.cos(np.pi * times / seconds)) / 2
    path = q0 + (q1 - q0) * s[:, None]
    trajectory = JointTrajectory(hw.arm.joint_names, times, path, np.gradient(path, times, axis=0))
    assert hw.kinematics is not None
    return Motion(
        angle=hw.angle + math.radians(turn_deg),
        T_base_camera=hw.kinematics.camera_pose(q1),
        q=q1,
        trajectory=trajectory,
        duration=seconds,
        overlapped=True,
    )


def test_frames_during_a_move_are_posed_by_the_joint_states_at_their_stamps(cell: FakeRos2Cell) -> None:
    cellfile = load_cell_file(cell.path)
    with open_rig(cellfile) as rig:
        hw = hardware_cell(rig)
        states = States(hw)
        images = Images(hw)
        hz = 10.0
        got: list[tuple[MoveFrame, float]] = []
        threads: set[str] = set()

        def on_frame(frame: MoveFrame) -> None:
            got.append((frame, time.time()))
            threads.add(threading.current_thread().name)

        motion = move(hw, [25.0, -10.0, 10.0, 15.0, 0.0, 30.0], turn_deg=40.0, seconds=0.7)
        hw.move_to(motion.T_base_camera, motion=motion, capture_hz=hz, on_frame=on_frame)
        stats = hw.last_move_stream
        assert stats is not None and stats.t0 is not None and stats.end is not None
        # nothing dropped but, maybe, a frame stamped before the move that was still on its way when it started
        assert stats.error == "" and stats.failed == 0, stats.summary()
        assert set(stats.dropped) <= {"before_history"} and stats.dropped.get("before_history", 0) <= 2, stats.summary()
        moved = stats.end - stats.t0
        assert 0.7 < moved < 2.5  # the trajectory, the settle, the discovery of the command's reader
        # the frame nearest each tick strictly inside the move (as the simulated cell's capture_times), by the test's
        # own record of the images' stamps; one per tick unless the camera fell behind at the move's end
        ticks = capture_times(moved, hz)
        expected = images.nearest(stats.t0, stats.end, ticks)
        assert threads == {"move-stream"}  # from the stream's thread, during the move
        ts = [f.t for f, _ in got]
        assert stats.delivered == len(got) == len(expected) >= len(ticks) - 1, stats.summary()
        assert np.allclose(ts, expected, atol=1e-6) and ts == sorted(ts) and ts[0] > 0 and ts[-1] < moved
        assert stats.received >= 0.6 * CAMERA_HZ * moved  # the camera streamed (the fake renders as fast as it can)
        # each pose: forward kinematics of the joints and the plate angle interpolated at the frame's stamp
        assert hw.kinematics is not None
        errors, between, moving = [], 0, 0
        for frame, _ in got:
            q, plate, _, differ = states.at(stats.t0 + frame.t)
            want = T_table_base(plate, cellfile.turntable_axis) @ hw.kinematics.camera_pose(q)
            errors.append(float(np.max(np.abs(frame.frame.T_world_camera.matrix - want.matrix))))
            stamps = np.array([r[0] for r in states.rows])
            nearest = states.rows[int(np.argmin(np.abs(stamps - (stats.t0 + frame.t))))]
            at_nearest = T_table_base(nearest[2], cellfile.turntable_axis) @ hw.kinematics.camera_pose(nearest[1])
            moving += differ
            between += differ and not np.allclose(frame.frame.T_world_camera.matrix, at_nearest.matrix, atol=1e-6)
            assert frame.frame.depth.shape == (120, 160) and frame.frame.depth.dtype == np.float32
        assert max(errors) < 1e-6, errors
        # while the arm moved, placed between two joint states, not at the nearest one
        assert moving >= len(got) - 3 and between >= moving - 1, (moving, between)
        latency = [arrived - (stats.t0 + f.t) for f, arrived in got]
        assert 0 < float(np.median(latency)) < 0.5
        print(
            f"\nmove {moved:.2f} s at {hz:g} Hz: {stats.delivered} frames of {len(ticks)} ticks, "
            f"{stats.received} received; pose error vs FK max {max(errors):.1e}; "
            f"stamp to on_frame median {np.median(latency) * 1000:.0f} ms, max {max(latency) * 1000:.0f} ms"
        )


def test_frames_outside_the_joint_states_are_dropped_with_their_reason_and_a_halt_ends_the_stream(
    cell: FakeRos2Cell,
) -> None:
    cellfile = load_cell_file(cell.path)
    cell.command("reset")
    with open_rig(cellfile) as rig:
        hw = hardware_cell(rig)
        states = States(hw)
        got: list[MoveFrame] = []

        def on_frame(frame: MoveFrame) -> None:
            got.append(frame)
            if len(got) == 1:
                raise RuntimeError("the consumer broke")

        motion = move(hw, [-20.0, 5.0, -5.0, 0.0, 10.0, -20.0], turn_deg=-30.0, seconds=1.0)
        # a frame stamped 30 s ago arrives during the move; later the joint states pause for 0.4 s
        threading.Timer(0.15, cell.command, ["stale_frame"]).start()
        threading.Timer(0.4, cell.command, ["pause_joints 0.4"]).start()
        hw.move_to(motion.T_base_camera, motion=motion, capture_hz=10.0, on_frame=on_frame)  # the move completes
        stats = hw.last_move_stream
        assert stats is not None and stats.t0 is not None and stats.end is not None
        assert stats.dropped.get("before_history") == 1, stats.summary()
        # the frames of the pause: in the gap, or (the first ones, the joint state after them still missing after
        # move_capture_wait_s) after the history
        paused = stats.dropped.get("gap", 0) + stats.dropped.get("after_history", 0)
        assert paused >= 4 and set(stats.dropped) <= {"before_history", "gap", "after_history"}, stats.summary()
        assert stats.failed == 1 and stats.delivered == len(got) - 1 >= 5
        print(f"\nfaults: {stats.summary()}")
        # the pause happened, and no frame was placed across it: each delivered one lies between two joint states
        # at most the gap limit apart
        stamps = np.array(sorted(r[0] for r in states.rows))
        inside = stamps[(stamps > stats.t0) & (stamps < stats.end)]
        assert float(np.max(np.diff(inside))) > 0.3
        assert max(states.at(stats.t0 + f.t)[2] for f in got) <= 0.2
        cell.command("reset")
        # a halt: the move stops, and so does the stream
        motion = move(hw, [20.0, -5.0, 5.0, 0.0, -10.0, 20.0], turn_deg=0.0, seconds=1.2)
        got.clear()
        halted_at: list[float] = []

        def halt() -> None:
            halted_at.append(time.monotonic())
            hw.halt()

        arrivals: list[float] = []

        def on_frame_timed(frame: MoveFrame) -> None:
            got.append(frame)
            arrivals.append(time.monotonic())

        threading.Timer(0.5, halt).start()
        with pytest.raises(DeviceError, match="stopped on request"):
            hw.move_to(motion.T_base_camera, motion=motion, capture_hz=10.0, on_frame=on_frame_timed)
        stats = hw.last_move_stream
        assert stats is not None
        assert stats.halted and 1 <= stats.delivered <= 6, stats.summary()
        assert all(a <= halted_at[0] + 0.05 for a in arrivals)
        print(f"\nhalted: {stats.summary()}")


def test_a_dry_run_of_the_cell_renders_its_move_frames_as_the_simulator_does(cell: FakeRos2Cell) -> None:
    from devices.config import CellConfig
    from devices.hwcell import dry_run_cell
    from tests.ros2.fakecell import CAMERA

    dry = dry_run_cell(load_cell_file(cell.path), CellConfig(), None, CAMERA, seed=0)
    from devices.motion import rz

    got: list[MoveFrame] = []
    motion = dry.move_to(rz(2.0) @ dry.initial_pose(), capture_hz=5.0, on_frame=got.append)  # the plate turns
    assert motion.duration > 0.3 and len(got) == len(capture_times(motion.duration, 5.0)) > 0
    assert dry.last_move_stream is None  # no device streamed: the simulator rendered them
    # on devices whose camera cannot stream, the move runs without capture and says why
    assert dry.kinematics is not None
    on_devices = HardwareCell(
        dry.camera,
        dry.arm,
        dry.turntable,
        dry.config,
        kinematics=dry.kinematics,
        cellfile=dry.cellfile,
        rig=object(),  # type: ignore[arg-type]  # devices that are not simulated (only its presence matters here)
    )
    got.clear()
    on_devices.move_to(dry.initial_pose(), capture_hz=5.0, on_frame=got.append)
    stats = on_devices.last_move_stream
    assert got == [] and stats is not None and "SimulatedCamera camera driver does not stream" in stats.error
    assert np.allclose(on_devices.pose.matrix, dry.initial_pose().matrix, atol=1e-3)  # the move ran
