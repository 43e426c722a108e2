"""A RealSense preset renders its depth stream's field of view (87 x 58 degrees), not the cell's 55 degree pinhole:
from the D405's working distance (about 0.33 m to B's centre, its 0.5 m range) the cell's pinhole cropped a fifth
of the object out of every view (docs/method.md, "Where the D405 and structured light lost recall")."""

from __future__ import annotations

import math

import numpy as np
import pytest
import trimesh

from devices.config import CameraConfig
from devices.sensors.presets import SensorModel, sensor_named
from devices.sim import SimulatedCamera
from planner.types import DepthFrame, Intrinsics, Pose

DOWN = np.array([[1.0, 0.0, 0.0], [0.0, -1.0, 0.0], [0.0, 0.0, -1.0]])


@pytest.mark.parametrize(("name", "size"), [("realsense-d435", (848, 480)), ("realsense-d405", (640, 360))])
def test_realsense_renders_its_stream(name: str, size: tuple[int, int]) -> None:
    """A floor 0.3 m below the camera: the image spans 2 * 0.3 * tan(87 / 2) = 0.569 m across and
    2 * 0.3 * tan(58 / 2) = 0.333 m down (the cell's pinhole: 0.315 x 0.236 m)."""
    floor = trimesh.creation.box(extents=(2.0, 2.0, 0.01))
    floor.apply_translation((0.0, 0.0, -0.005))
    camera = SimulatedCamera(floor, CameraConfig(sensor=name), plate_radius=0.0)
    k = camera.intrinsics
    assert (k.width, k.height) == size
    assert k.fx == pytest.approx(size[0] / 2 / math.tan(math.radians(43.5)))
    pose = Pose(DOWN, np.array([0.0, 0.0, 0.3]))
    frame = DepthFrame(camera.render(pose), pose, k)
    assert np.all(frame.depth > 0)
    points = frame.points_world
    x_span, y_span = np.ptp(points[:, 0]), np.ptp(points[:, 1])
    assert x_span == pytest.approx(2 * 0.3 * math.tan(math.radians(43.5)), rel=0.01)
    assert y_span == pytest.approx(2 * 0.3 * math.tan(math.radians(29.0)), rel=0.01)


def test_cell_pinhole_where_no_stream_is_given_or_one_is_set() -> None:
    mesh = trimesh.creation.icosphere()
    assert SimulatedCamera(mesh, CameraConfig()).intrinsics == Intrinsics()  # ideal: today's camera
    assert SimulatedCamera(mesh, CameraConfig(sensor="structured-light")).intrinsics == Intrinsics()
    own = CameraConfig(sensor="realsense-d405", width=320, height=240, fx=300.0, fy=300.0, cx=159.5, cy=119.5)
    assert SimulatedCamera(mesh, own).intrinsics == own.intrinsics  # a pinhole set explicitly wins
    assert sensor_named("realsense-d405").focal_px == pytest.approx(640 / math.tan(math.radians(43.5)))


def test_bad_field_of_view() -> None:
    with pytest.raises(ValueError, match=r"sensor\.fov_deg"):
        SensorModel("bad", fov_deg=(200.0, 50.0), render_size=(10, 10))
    with pytest.raises(ValueError, match=r"sensor\.render_size"):
        SensorModel("bad", fov_deg=(80.0, 50.0))
