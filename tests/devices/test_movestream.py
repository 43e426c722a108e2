"""The placing of frames streamed during a move (devices/movestream.py), on hand-made stamps: the interpolation
between joint states, the frames dropped by reason, the rate's choice of the frame nearest each tick, delivery
faults that do not end the stream, and a stop. The same over DDS with the ROS 2 drivers: tests/ros2/."""

from __future__ import annotations

import math
import threading
import time

import numpy as np
import pytest

from devices.movestream import (
    FrameQueue,
    MoveStreamer,
    MoveStreamLimits,
    PolledSeries,
    StampedFrame,
    StampedSeries,
)
from planner.types import DepthFrame, Intrinsics, Pose

K = Intrinsics(4, 3, 5.0, 5.0, 1.5, 1.0)
T0 = 1_700_000_000.0  # stamps are on an epoch clock, as ROS time and the RealSense's global time are


def frame_at(stamp: float | None, arrival: float | None = None, reason: str = "") -> StampedFrame:
    depth = np.full((3, 4), 0.5 if stamp is None else 0.5 + (stamp - T0) * 0.01, dtype=np.float32)
    return StampedFrame(stamp, lambda: DepthFrame(depth, Pose.identity(), K), arrival or time.monotonic(), reason)


def joints_of_t(t: float) -> np.ndarray:
    """A joint path that is not linear in time (so interpolating it is not the same as evaluating it)."""
    return np.array([math.sin(t), t * t, 0.3 * t])


def pose_of(q: np.ndarray, theta: float) -> Pose:
    """A stand-in for forward kinematics: the joints as the position, the plate angle as a turn about z."""
    c, s = math.cos(theta), math.sin(theta)
    return Pose(np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]]), q[:3].copy())


def histories(stamps: np.ndarray) -> tuple[StampedSeries, StampedSeries]:
    joints, plate = StampedSeries(), StampedSeries()
    for s in stamps:
        joints.add(T0 + s, joints_of_t(s))
        plate.add(T0 + s, 0.5 * s)
    return joints, plate


def run(
    frames: list[StampedFrame],
    joints: StampedSeries,
    plate: StampedSeries,
    hz: float,
    end: float,
    deliver=None,
    limits: MoveStreamLimits | None = None,
):
    got: list[tuple[DepthFrame, float]] = []
    queue = FrameQueue()
    for f in frames:
        queue.put(f)
    streamer = MoveStreamer(
        queue,
        joints,
        plate,
        pose_of,
        T0,
        hz,
        deliver or (lambda frame, t: got.append((frame, t))),
        limits or MoveStreamLimits(wait_s=0.05),
    )
    stats = streamer.finish(T0 + end)
    return got, stats


def test_a_series_interpolates_between_the_bracketing_stamps_and_says_why_it_cannot() -> None:
    series = StampedSeries()
    series.add(10.0, np.array([0.0, 1.0]))
    series.add(10.01, np.array([1.0, 3.0]))
    series.add(10.2, np.array([2.0, 3.0]))  # 0.19 s later: a gap
    series.add(10.15, np.array([9.0, 9.0]))  # older than the last: ignored
    assert series.out_of_order == 1 and len(series) == 3
    value, why = series.at(10.0025, max_gap_s=0.05)
    assert why == "" and value is not None and np.allclose(value, [0.25, 1.5], atol=1e-9)
    value, _ = series.at(10.01, max_gap_s=0.05)
    assert value is not None and np.array_equal(value, [1.0, 3.0])
    assert series.at(9.999, 0.05) == (None, "before_history")
    assert series.at(10.2001, 0.05) == (None, "after_history")
    assert series.at(10.1, 0.05) == (None, "gap")
    value, why = series.at(10.1, 0.5)
    assert why == "" and value is not None and np.allclose(value, [1.0 + 0.09 / 0.19, 3.0])
    # an angle series takes the short way round at pi
    angles = StampedSeries(angle=True)
    angles.add(0.0, math.pi - 0.1)
    angles.add(1.0, -math.pi + 0.1)
    value, _ = angles.at(0.5, 2.0)
    assert value is not None and abs(abs(float(value[0])) - math.pi) < 1e-9


def test_each_tick_gets_the_nearest_frame_posed_at_its_interpolated_joints() -> None:
    joint_stamps = np.arange(0.0, 1.0001, 0.01)  # 100 Hz
    joints, plate = histories(joint_stamps)
    frame_stamps = 0.004 + np.arange(0, 30) / 30.0  # 30 Hz, between joint states
    got, stats = run([frame_at(T0 + s) for s in frame_stamps], joints, plate, hz=5.0, end=1.0)
    assert stats.received == 30 and stats.placed == 30 and stats.dropped == {}
    assert stats.delivered == len(got) == 4  # ticks 0.2, 0.4, 0.6, 0.8: strictly inside the move
    assert stats.skipped == 26 and stats.failed == 0 and stats.error == ""
    ts = [t for _, t in got]
    assert ts == sorted(ts)
    for k, (frame, t) in enumerate(got, start=1):
        nearest = frame_stamps[np.argmin(np.abs(frame_stamps - k * 0.2))]
        assert t == pytest.approx(nearest, abs=1e-6)
        i = int(np.searchsorted(joint_stamps, t)) - 1
        w = (t - joint_stamps[i]) / (joint_stamps[i + 1] - joint_stamps[i])
        q = (1 - w) * joints_of_t(joint_stamps[i]) + w * joints_of_t(joint_stamps[i + 1])
        want = pose_of(q, 0.5 * t)
        assert np.allclose(frame.T_world_camera.matrix, want.matrix, atol=1e-9)
        # the pose between two joint states, not the nearest one's
        assert not np.allclose(frame.T_world_camera.translation, joints_of_t(joint_stamps[i]), atol=1e-6)
        assert frame.depth[0, 0] == pytest.approx(0.5 + t * 0.01, abs=1e-6)  # its own image
    assert len(stats.latency_s) == 4


def test_frames_that_cannot_be_placed_are_dropped_with_their_reason() -> None:
    stamps = np.concatenate([np.arange(0.0, 0.4001, 0.01), np.arange(0.6, 1.0001, 0.01)])  # no states in 0.4..0.6
    joints, plate = histories(stamps)
    frames = [
        frame_at(T0 - 5.0),  # long before the move
        frame_at(T0 + 0.1),
        frame_at(T0 + 0.05),  # older than the frame before it
        frame_at(None, reason="hardware clock"),
        frame_at(T0 + 0.5),  # in the joint states' gap
        frame_at(T0 + 0.8),
        frame_at(T0 + 1.02),  # after the move's end
    ]
    got, stats = run(frames, joints, plate, hz=2.0, end=1.0)
    assert stats.dropped == {"before_history": 1, "out_of_order": 1, "clock": 1, "gap": 1}
    assert stats.placed == 2 and stats.after_move == 1
    # the tick at 0.5 takes the nearer placed frame (0.8, not 0.1); the move ends at the next tick
    assert [round(t, 6) for _, t in got] == [0.8] and stats.skipped == 1
    # a frame after the last joint state: none comes within wait_s
    joints, plate = histories(np.arange(0.0, 0.5001, 0.01))
    got, stats = run([frame_at(T0 + 0.3), frame_at(T0 + 0.7)], joints, plate, hz=2.0, end=1.0)
    assert stats.dropped == {"after_history": 1} and [round(t, 6) for _, t in got] == [0.3]


def test_a_frame_waits_for_the_joint_state_after_its_stamp() -> None:
    joints, plate = histories(np.arange(0.0, 0.3001, 0.01))
    queue = FrameQueue()
    got: list[float] = []
    streamer = MoveStreamer(
        queue, joints, plate, pose_of, T0, 4.0, lambda f, t: got.append(t), MoveStreamLimits(wait_s=0.3)
    )
    queue.put(frame_at(T0 + 0.255))
    queue.put(frame_at(T0 + 0.33))  # the joint state after it arrives 0.1 s later

    def late_states() -> None:
        time.sleep(0.1)
        for s in np.arange(0.31, 0.5001, 0.01):
            joints.add(T0 + s, joints_of_t(s))
            plate.add(T0 + s, 0.5 * s)

    threading.Thread(target=late_states).start()
    stats = streamer.finish(T0 + 0.51)
    assert stats.dropped == {} and stats.placed == 2
    assert [round(t, 6) for t in got] == [0.255, 0.33]  # the ticks at 0.25 and 0.5 (the last one by the flush)


def test_a_failing_delivery_is_counted_and_the_stream_goes_on_and_a_stop_ends_it() -> None:
    joints, plate = histories(np.arange(0.0, 1.0001, 0.01))
    calls: list[float] = []

    def deliver(frame: DepthFrame, t: float) -> None:
        calls.append(t)
        if len(calls) == 2:
            raise RuntimeError("the consumer broke")

    _, stats = run([frame_at(T0 + s) for s in np.arange(0.01, 1.0, 0.05)], joints, plate, 5.0, 1.0, deliver)
    assert len(calls) == 4 and stats.failed == 1 and stats.delivered == 3 and stats.error == ""
    # a stop (a halt): nothing is delivered after it
    queue = FrameQueue()
    delivered: list[float] = []
    streamer = MoveStreamer(queue, joints, plate, pose_of, T0, 5.0, lambda f, t: delivered.append(t))
    queue.put(frame_at(T0 + 0.21))
    time.sleep(0.2)
    streamer.stop()
    queue.put(frame_at(T0 + 0.41))  # the queue is closed: not even received
    stats = streamer.finish(T0 + 1.0)
    assert stats.halted and delivered == pytest.approx([0.21])
    assert queue.closed and stats.received == 1


def test_limits_and_rates_are_checked() -> None:
    with pytest.raises(ValueError, match="max_gap_s: must be > 0"):
        MoveStreamLimits(max_gap_s=0.0)
    with pytest.raises(ValueError, match="hz: must be > 0"):
        MoveStreamer(FrameQueue(), StampedSeries(), StampedSeries(), pose_of, T0, 0.0, lambda f, t: None)


def test_a_polled_series_stamps_with_the_host_clock_and_skips_failed_reads() -> None:
    reads = [0]

    def read() -> float:
        reads[0] += 1
        if reads[0] % 3 == 0:
            raise OSError("a missed read")
        return float(reads[0])

    before = time.time()
    polled = PolledSeries(read, hz=200.0)
    deadline = time.monotonic() + 5.0  # 0.1 s at 200 Hz, or longer when a loaded machine schedules the poller late
    while len(polled.series) < 5 and time.monotonic() < deadline:
        time.sleep(0.02)
    polled.close()
    stamps, values = polled.series.snapshot()
    assert len(stamps) >= 5 and before <= stamps[0] and stamps[-1] <= time.time()
    assert not np.any(values[:, 0] % 3 == 0)  # the failed reads left no value


def test_a_resting_value_holds_until_the_next_one() -> None:
    series = StampedSeries()
    series.add(1.0, 0.5, rest=True)
    series.add(3.0, 0.5, rest=True)  # still there two seconds later: no gap in between
    value, why = series.at(2.0, max_gap_s=0.1)
    assert why == "" and value is not None and value[0] == 0.5
    assert series.wait_past(100.0, timeout=0.0)  # resting last: it covers every later stamp
    value, _ = series.at(100.0, 0.1)
    assert value is not None and value[0] == 0.5
    series.add(3.05, 0.6)  # moving again
    assert series.at(3.2, 0.1) == (None, "after_history")
    value, _ = series.at(3.025, 0.1)
    assert value is not None and value[0] == pytest.approx(0.55)
    series.add(3.5, 1.0, rest=True)
    assert series.at(3.3, 0.1) == (None, "gap")  # a moving value before it: the gap rule holds


def test_a_frame_stamped_after_the_marked_end_of_the_move_is_not_delivered_before_finish_is_called() -> None:
    """The arm's history goes on after the move (a polled arm is read until the stream ends): once the move's end is
    marked on it, a frame stamped later is after the move even while ``finish`` has not been called yet, and the
    tick past the end gets no frame."""
    stamps = np.arange(0.0, 0.5001, 0.01)
    joints, plate = histories(stamps)
    assert joints.end is None
    assert joints.end_move() == pytest.approx(T0 + 0.5) and joints.end == pytest.approx(T0 + 0.5)
    for s in np.arange(0.51, 0.8, 0.01):  # polled on after the move's end
        joints.add(T0 + s, joints_of_t(s))
        plate.add(T0 + s, 0.5 * s)
    assert joints.end_move() == pytest.approx(T0 + 0.5)  # marked once
    got: list[float] = []
    queue = FrameQueue()
    for s in (0.09, 0.21, 0.29, 0.41, 0.52, 0.61, 0.72):
        queue.put(frame_at(T0 + s))
    streamer = MoveStreamer(
        queue, joints, plate, pose_of, T0, 10.0, lambda frame, t: got.append(t), MoveStreamLimits(wait_s=0.05)
    )
    deadline = time.monotonic() + 5.0
    while streamer.stats.received < 5 and time.monotonic() < deadline:  # up to the first frame after the end
        time.sleep(0.01)
    time.sleep(0.05)
    assert streamer.stats.after_move == 1 and streamer.stats.received == 5, streamer.stats
    stats = streamer.finish(joints.end)
    # ticks 0.1 .. 0.4 (0.5 is the end, not inside the move): each its nearest frame of the move, none after it
    assert got == pytest.approx([0.09, 0.21, 0.29, 0.41], abs=1e-6)
    assert stats.delivered == 4 and stats.placed == 4 and stats.after_move == 1 and stats.end == T0 + 0.5
