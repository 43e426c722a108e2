"""Capture during moves: the camera's path along a move as the cell executes it, the frames a simulated cell takes
there, and the timing model (a frame's pose error grows with the move's speed and the stamp latency)."""

from __future__ import annotations

import dataclasses
import math

import numpy as np
import pytest

from devices.angles import wrap_angle
from devices.arm.config import ArmConfig
from devices.builtins import make_builtin
from devices.cell import Cell, Motion
from devices.config import CameraConfig, CellConfig
from devices.move_capture import MoveFrame, MovePath, SimulatedMoveCapture, blurred, camera_path, capture_times
from devices.sensors import SensorModel
from devices.sim import make_sim_cell
from planner.types import Pose
from tests.helpers import orbit_view

TARGET = np.array([0.0, 0.0, 0.08])
SMALL = CameraConfig(width=80, height=60, fx=76.0, fy=76.0, cx=39.5, cy=29.5)


def _azimuth(T: Pose) -> float:
    return math.atan2(T.translation[1], T.translation[0])


def _pose_gap(a: Pose, b: Pose) -> float:
    return float(np.linalg.norm(a.translation - b.translation))


@pytest.fixture(scope="module")
def bunny_cell() -> Cell:
    return make_sim_cell(make_builtin("l-block", 0.2), SMALL, CellConfig(), seed=0)


def test_the_path_starts_where_the_camera_is_and_ends_at_the_view(bunny_cell: Cell) -> None:
    for overlapped in (False, True):
        cell = make_sim_cell(
            make_builtin("l-block", 0.2), SMALL, CellConfig(arm=ArmConfig(turn_while_moving=overlapped)), seed=0
        )
        view = orbit_view(TARGET, 40, 100, 0.45)
        motion = cell.plan_motion(view)
        start = cell.pose
        path = MovePath.of(cell, motion)
        assert path.duration == pytest.approx(motion.duration, abs=1e-9)
        assert path.turn_seconds > 0.3  # the plate turns: the path's two parts both matter
        first, last = camera_path(cell, motion, [0.0, motion.duration])
        np.testing.assert_allclose(first.matrix, start.matrix, atol=1e-9)
        np.testing.assert_allclose(last.matrix, view.matrix, atol=1e-6)
        cell.move_to(view, motion=motion)
        np.testing.assert_allclose(cell.pose.matrix, last.matrix, atol=1e-9)


def test_a_plate_only_move_sweeps_the_camera_azimuth_in_the_table_frame(bunny_cell: Cell) -> None:
    cell = bunny_cell
    q = cell.joint_positions()
    assert q is not None and cell.kinematics is not None
    turn = math.radians(90.0)
    hold = Motion(
        wrap_angle(cell.angle + turn),
        cell.T_base_camera,
        q,
        trajectory=_hold(cell),
        duration=turn / math.radians(ArmConfig().turntable_speed_deg),
    )
    path = MovePath.of(cell, hold)
    assert path.duration == pytest.approx(2.0)  # 90 degrees at 45 degrees/s
    times = np.linspace(0.0, path.duration, 9)
    azimuths = np.unwrap([_azimuth(T) for T in camera_path(cell, hold, times)])
    # the plate turns by +theta, so the camera (still in the base frame) turns by -theta in the table frame
    np.testing.assert_allclose(azimuths - azimuths[0], -turn * times / path.duration, atol=1e-9)
    heights = [T.translation[2] for T in path.poses(times)]
    assert np.ptp(heights) < 1e-12


def _hold(cell: Cell):
    from devices.trajectory import JointTrajectory

    q = cell.joint_positions()
    assert q is not None and cell.kinematics is not None
    return JointTrajectory.hold(cell.kinematics.joint_names, q)


def test_the_views_speed_during_a_plate_turn_is_the_turn_rate_times_radius_plus_reach(bunny_cell: Cell) -> None:
    path = _plate_path(bunny_cell, 45.0)
    radius = float(np.hypot(*bunny_cell.pose.translation[:2]))
    rate = math.radians(45.0)
    assert path.speed_at(path.duration / 2) == pytest.approx(rate * (radius + 0.4), rel=1e-3)
    assert path.speed_at(path.duration + 1.0) == 0.0  # after the move: still


def test_the_reach_sphere_turns_then_travels_straight() -> None:
    cell = make_sim_cell(None, SMALL, CellConfig(kinematics="reach_sphere"), seed=0)
    start = cell.pose
    view = orbit_view(TARGET, 50, 140, 0.4)
    motion = cell.plan_motion(view)
    path = MovePath.of(cell, motion)
    assert path.duration == pytest.approx(motion.duration, abs=1e-9)
    assert path.turn_seconds > 0 and path.travel_seconds > 0
    at_turn = path.T_table_camera(path.turn_seconds)
    middle = path.T_table_camera(path.turn_seconds + path.travel_seconds / 2)
    np.testing.assert_allclose(path.T_table_camera(0).matrix, start.matrix, atol=1e-12)
    np.testing.assert_allclose(path.T_table_camera(path.duration).matrix, view.matrix, atol=1e-9)
    np.testing.assert_allclose(middle.translation, (at_turn.translation + view.translation) / 2, atol=1e-9)


def test_capture_times_are_strictly_inside_the_move() -> None:
    np.testing.assert_allclose(capture_times(2.0, 2.5), [0.4, 0.8, 1.2, 1.6])
    np.testing.assert_allclose(capture_times(2.1, 2.5), [0.4, 0.8, 1.2, 1.6, 2.0])
    assert len(capture_times(0.3, 2.5)) == 0 and len(capture_times(5.0, 0.0)) == 0
    with pytest.raises(ValueError, match="capture_hz"):
        capture_times(1.0, -1.0)
    with pytest.raises(ValueError, match="t: "):
        MoveFrame(make_sim_cell(None, SMALL, CellConfig(kinematics="reach_sphere")).capture(), -0.1)


class _TimedCamera:
    """A stand-in for the simulated camera with a chosen timing model (only its sensor is read here)."""

    def __init__(self, latency: float, sensor: SensorModel | None = None) -> None:
        self.sensor = sensor if sensor is not None else SensorModel("timed", stamp_latency=latency)


def _plate_path(cell: Cell, speed_deg: float) -> MovePath:
    q = cell.joint_positions()
    motion = Motion(wrap_angle(cell.angle + math.radians(120)), cell.T_base_camera, q, trajectory=_hold(cell))
    path = MovePath.of(cell, motion)
    return dataclasses.replace(path, turn_speed=math.radians(speed_deg))


@pytest.mark.parametrize("latency", [0.005, 0.02])
def test_a_frames_pose_error_grows_with_the_moves_speed_and_the_latency(bunny_cell: Cell, latency: float) -> None:
    cell = bunny_cell
    radius = float(np.hypot(*cell.pose.translation[:2]))
    errors = {}
    for speed_deg in (15.0, 45.0, 90.0):
        path = _plate_path(cell, speed_deg)
        capture = SimulatedMoveCapture(_TimedCamera(latency))  # type: ignore[arg-type]
        stamp = path.duration / 2
        (exposed,) = capture.exposure_times(stamp)
        assert exposed == pytest.approx(stamp - latency)
        gap = _pose_gap(capture.true_pose(path, exposed), path.T_table_camera(stamp))
        # the plate carries the camera (in the table frame) along a circle: the error is the arc in the latency
        expected = 2 * radius * math.sin(math.radians(speed_deg) * latency / 2)
        assert gap == pytest.approx(expected, rel=1e-6)
        errors[speed_deg] = gap
    assert errors[15.0] < errors[45.0] < errors[90.0]
    assert errors[90.0] / errors[15.0] == pytest.approx(6.0, rel=1e-3)


def test_no_latency_no_error_and_jitter_spreads_the_exposure(bunny_cell: Cell) -> None:
    path = _plate_path(bunny_cell, 45.0)
    ideal = SimulatedMoveCapture(_TimedCamera(0.0))  # type: ignore[arg-type]
    (t,) = ideal.exposure_times(1.0)
    assert t == 1.0 and _pose_gap(ideal.true_pose(path, t), path.T_table_camera(1.0)) < 1e-12
    sensor = SensorModel("jitter", stamp_latency=0.01, stamp_jitter=0.004, exposure=0.008)
    jittery = SimulatedMoveCapture(_TimedCamera(0.0, sensor), seed=3)  # type: ignore[arg-type]
    draws = np.array([jittery.exposure_times(1.0) for _ in range(400)])  # (400, 3): start, middle, end
    assert draws.shape == (400, 3)
    np.testing.assert_allclose(draws[:, 2] - draws[:, 0], 0.008, atol=1e-12)
    assert np.mean(draws[:, 1]) == pytest.approx(1.0 - 0.01, abs=0.001)
    assert np.std(draws[:, 1]) == pytest.approx(0.004, rel=0.15)


def test_blur_drops_mixed_pixels_and_averages_the_rest() -> None:
    plain = np.array([[[1.0, 0.5, 0.0]], [[1.002, 0.7, 0.4]], [[1.004, 0.9, 0.4]]], dtype=np.float32)  # (3, 1, 3)
    out = blurred(plain, None, 0.01)
    np.testing.assert_allclose(out, [[1.002, 0.0, 0.0]], atol=1e-6)  # a jump, a pixel seen at some times only
    measured = np.array([[1.01, 0.7, 0.4]], dtype=np.float32)
    np.testing.assert_allclose(blurred(plain, measured, 0.01), [[1.01, 0.0, 0.0]], atol=1e-6)


def test_a_move_with_capture_calls_back_with_frames_at_the_rate_in_stamp_order(bunny_cell: Cell) -> None:
    cell = make_sim_cell(make_builtin("l-block", 0.2), SMALL, CellConfig(), seed=0)
    view = orbit_view(TARGET, 30, -120, 0.45)
    motion = cell.plan_motion(view)
    path = MovePath.of(cell, motion)
    got: list[MoveFrame] = []
    cell.move_to(view, motion=motion, capture_hz=5.0, on_frame=got.append)
    stamps = [f.t for f in got]
    np.testing.assert_allclose(stamps, capture_times(motion.duration, 5.0))
    assert len(got) >= 3
    for f in got:
        np.testing.assert_allclose(f.frame.T_world_camera.matrix, path.T_table_camera(f.t).matrix, atol=1e-12)
    assert sum(int(f.frame.valid.sum()) for f in got) > 0  # the object is seen on the way
    reference = make_sim_cell(make_builtin("l-block", 0.2), SMALL, CellConfig(), seed=0).camera
    for f in got:  # the ideal sensor: the frame is the render from the pose of its stamp
        np.testing.assert_allclose(f.frame.depth, reference.render(f.frame.T_world_camera), atol=1e-6)  # type: ignore[attr-defined]
    with pytest.raises(ValueError, match="capture_hz"):
        cell.move_to(orbit_view(TARGET, 30, 0, 0.45), capture_hz=math.nan, on_frame=got.append)
    assert len(got) == len(stamps)  # nothing moved, nothing taken
