"""The RealSense driver on a recording written by librealsense's software device (no camera needed)."""

from __future__ import annotations

import numpy as np
import pytest

from devices.drivers.realsense import RealSenseCamera, RealSenseConfig
from devices.protocols import Camera, CaptureError, DeviceError
from tests.devices.drivers.rsfixtures import DEPTH_UNIT, record_views


@pytest.fixture(scope="module")
def recording(tmp_path_factory):
    return record_views(tmp_path_factory.mktemp("rs"), n=3)


def open_camera(path, **overrides) -> RealSenseCamera:
    return RealSenseCamera(RealSenseConfig(width=80, height=60, playback=str(path), min_depth=0.05, **overrides))


def test_captures_equal_the_rendered_depth_within_one_depth_unit(recording):
    path, depths, k = recording
    with open_camera(path) as camera:
        assert isinstance(camera, Camera)
        assert camera.intrinsics == k  # read from the stream profile, not typed in
        assert camera.depth_scale == pytest.approx(DEPTH_UNIT, rel=1e-6)
        for rendered in depths:
            frame = camera.capture()
            assert frame.depth.dtype == np.float32 and frame.depth.shape == (60, 80)
            assert np.array_equal(frame.depth > 0, rendered > 0)
            assert np.max(np.abs(frame.depth - rendered)) <= DEPTH_UNIT
            assert np.allclose(frame.T_world_camera.matrix, np.eye(4))
        assert camera.captures == 3
        assert "80x60" in camera.describe()


def test_past_the_end_of_the_recording_is_a_capture_error_after_the_timeout(recording):
    path, _, _ = recording
    with open_camera(path, timeout_s=0.3) as camera:
        for _ in range(3):
            camera.capture()
        with pytest.raises(CaptureError, match=r"no depth frame within 0.3 s"):
            camera.capture()
        assert camera.captures == 3


def test_averaging_takes_the_mean_of_the_frames_with_a_return(recording):
    path, depths, _ = recording
    with open_camera(path, average=2) as camera:
        frame = camera.capture()
    a, b = depths[0].astype(np.float64), depths[1].astype(np.float64)
    count = (a > 0).astype(int) + (b > 0)
    want = np.divide(a + b, count, out=np.zeros_like(a), where=count > 0)
    assert np.array_equal(frame.depth > 0, count > 0)
    assert np.max(np.abs(frame.depth - want)) <= DEPTH_UNIT
    # a pixel seen in one frame only keeps that frame's depth (not halved)
    only_a = (a > 0) & (b == 0)
    assert only_a.any()
    assert np.max(np.abs(frame.depth[only_a] - a[only_a])) <= DEPTH_UNIT


def test_depth_range_cuts_returns(recording):
    path, depths, _ = recording
    with open_camera(path, max_depth=0.45) as camera:
        frame = camera.capture()
    rendered = depths[0]
    assert np.all(frame.depth[rendered > 0.45 + DEPTH_UNIT] == 0)
    near = (rendered > 0) & (rendered < 0.45 - DEPTH_UNIT)
    assert near.any() and np.all(frame.depth[near] > 0)


def test_hole_filling_fills_the_pixels_without_a_return(recording):
    path, depths, _ = recording
    with open_camera(path, filters=["hole_filling"], max_depth=3.0) as camera:
        frame = camera.capture()
    holes = depths[0] == 0
    assert holes.any()
    assert np.count_nonzero(frame.depth == 0) < np.count_nonzero(holes)
    seen = depths[0] > 0  # pixels that had a return keep it
    assert np.max(np.abs(frame.depth[seen] - depths[0][seen])) <= DEPTH_UNIT


def test_spatial_and_temporal_filters_run_and_keep_the_image_size(recording):
    path, depths, _ = recording
    with open_camera(path, filters=["spatial", "temporal"]) as camera:
        frame = camera.capture()
    assert frame.depth.shape == (60, 80)
    seen = (frame.depth > 0) & (depths[0] > 0)
    assert seen.sum() > 0.5 * (depths[0] > 0).sum()
    assert np.median(np.abs(frame.depth[seen] - depths[0][seen])) < 0.005  # smoothing, not a different image


def test_a_resolution_the_recording_lacks_is_a_device_error_naming_it(recording):
    path, _, _ = recording
    with pytest.raises(DeviceError, match=r"cannot start a 640x480 z16 depth stream at 30 fps from recording"):
        RealSenseCamera(RealSenseConfig(playback=str(path)))


def test_a_missing_recording_is_a_device_error(tmp_path):
    with pytest.raises(DeviceError, match=r"playback file .*nope.db3.* not found"):
        RealSenseCamera(RealSenseConfig(playback=str(tmp_path / "nope.db3")))


@pytest.mark.parametrize(
    ("overrides", "message"),
    [
        ({"width": 0}, r"devices.camera.width: must be an integer >= 1, got 0"),
        ({"filters": ["median"]}, r"devices.camera.filters: unknown filter 'median'"),
        ({"average": True}, r"devices.camera.average: must be an integer >= 1"),
        ({"timeout_s": 0.0}, r"devices.camera.timeout_s: must be > 0"),
        ({"max_depth": 0.05}, r"devices.camera.max_depth: must be > min_depth"),
    ],
)
def test_bad_config_names_the_field(overrides, message):
    with pytest.raises(ValueError, match=message):
        RealSenseConfig(**overrides)


def test_played_back_captures_back_project_to_the_rendered_points(tmp_path):
    """With the poses they were rendered from, the captures give the planner the rendered scene: the same
    pixels back-project (intrinsics from the stream profile) to world points within the depth rounding."""
    from planner.types import DepthFrame, Pose

    path, depths, k = record_views(tmp_path, n=3)
    with open_camera(path) as camera:
        for i, depth in enumerate(depths):
            a = 2 * np.pi * i / 3
            pose = Pose.look_at((0.45 * np.cos(a), 0.45 * np.sin(a), 0.3), (0.0, 0.0, 0.06))
            rendered = DepthFrame(depth, pose, k).points_world
            played = camera.capture().with_pose(pose).points_world
            assert played.shape == rendered.shape and len(played) > 1000
            # a depth error dz moves a point by dz * |(x/z, y/z, 1)| < 1.5 dz in this field of view
            assert np.max(np.linalg.norm(played - rendered, axis=1)) <= 1.5 * DEPTH_UNIT
