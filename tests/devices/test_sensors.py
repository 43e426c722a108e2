"""The sensor models' effects, measured on simple scenes with real ray casting (devices.sensors, SimulatedCamera)."""

from __future__ import annotations

import math

import numpy as np
import pytest
import trimesh

from devices.config import CameraConfig
from devices.sensors import SENSORS, SensorModel, sensor_named
from devices.sensors.depth_effects import discontinuities
from devices.sim import SimulatedCamera
from planner.types import Pose

DOWN = np.array([[1.0, 0.0, 0.0], [0.0, -1.0, 0.0], [0.0, 0.0, -1.0]])
"""Camera looking straight down -z, its +x along the world's +x."""


def floor(size: float = 3.0) -> trimesh.Trimesh:
    """A slab whose top is the plane z = 0."""
    slab = trimesh.creation.box(extents=(size, size, 0.02))
    slab.apply_translation((0.0, 0.0, -0.01))
    return slab


def step(edge_x: float, height: float) -> trimesh.Trimesh:
    """The floor plus a block of ``height`` covering x > ``edge_x``."""
    block = trimesh.creation.box(extents=(1.0, 1.0, height))
    block.apply_translation((edge_x + 0.5, 0.0, height / 2))
    return trimesh.util.concatenate([floor(), block])


def camera(mesh: trimesh.Trimesh, sensor: SensorModel, seed: int = 0) -> SimulatedCamera:
    cam = SimulatedCamera(mesh, CameraConfig(min_depth=0.01, max_depth=5.0), plate_radius=0.0, seed=seed)
    cam.sensor = sensor
    return cam


def only(name: str, **fields: object) -> SensorModel:
    """The preset ``name`` with every effect off except its noise model and ``fields``."""
    base = sensor_named(name)
    keep = {"baseline": base.baseline, "subpixel": base.subpixel, "focal_px": base.focal_px}
    return SensorModel(f"{name}-only", **keep, **fields)  # type: ignore[arg-type]


@pytest.mark.parametrize("name", ["realsense-d435", "realsense-d405", "structured-light"])
@pytest.mark.parametrize("height", [0.3, 0.5])
def test_depth_noise_on_a_plane_matches_the_model(name: str, height: float) -> None:
    sensor = only(name)
    cam = camera(floor(), sensor)
    depth = cam.render_sensor(Pose(DOWN, np.array([0.0, 0.0, height])))
    valid = depth > 0
    assert valid.mean() > 0.99  # a plane seen face on by both viewpoints: nothing lost
    measured = float(np.std(depth[valid].astype(np.float64) - height))
    model = sensor.depth_rms(height)
    assert abs(measured - model) <= 0.2 * model, (measured, model)


def test_d435_noise_figures() -> None:
    """The D435 model at its own figures: 0.08 px subpixel, 50 mm baseline, 848 px wide at 87 degrees."""
    d435 = sensor_named("realsense-d435")
    focal = 424 / math.tan(math.radians(43.5))
    assert d435.depth_rms(0.5) == pytest.approx(0.25 * 0.08 / (focal * 0.05))
    assert 0.0008 < d435.depth_rms(0.5) < 0.0011  # about 1 mm at half a metre


def tilted(angle_deg: float, height: float) -> Pose:
    """The downward camera turned by ``angle_deg`` about its x axis, ``height`` above the floor."""
    a = math.radians(angle_deg)
    turn = np.array([[1.0, 0.0, 0.0], [0.0, math.cos(a), -math.sin(a)], [0.0, math.sin(a), math.cos(a)]])
    return Pose(DOWN @ turn, np.array([0.0, 0.0, height]))


def test_no_depth_beyond_the_grazing_limit() -> None:
    limit = 70.0
    cam = camera(floor(), SensorModel("grazing", max_incidence_deg=limit))
    pose = tilted(60.0, 0.3)  # rays from 33 to 87 degrees off the floor's normal
    depth = cam.render_sensor(pose)
    k = cam.intrinsics
    v, u = np.mgrid[0 : k.height, 0 : k.width]
    rays = pose.rotation @ np.stack([(u - k.cx) / k.fx, (v - k.cy) / k.fy, np.ones_like(u, dtype=float)]).reshape(3, -1)
    incidence = np.degrees(np.arccos(np.abs(rays[2]) / np.linalg.norm(rays, axis=0))).reshape(k.height, k.width)
    assert not np.any(depth[incidence > limit + 0.01] > 0)
    assert np.all(depth[incidence < limit - 0.01] > 0)
    assert np.any(incidence > limit + 5) and np.any(incidence < limit - 5)  # the scene spans the limit


def test_shadow_band_beside_a_step_matches_the_geometry() -> None:
    """A second viewpoint ``b`` to the camera's +x loses the floor beside a block's edge (block on the +x side):
    a band of width b (D - d) / d on the floor, D the floor's depth, d the block top's."""
    b, D, H, edge = 0.05, 0.5, 0.1, 0.02
    cam = camera(step(edge, H), SensorModel("shadow", baseline=b))
    depth = cam.render_sensor(Pose(DOWN, np.array([0.0, 0.0, D])))
    k = cam.intrinsics
    row = depth[int(k.cy)]
    u_top = int(np.argmax(np.abs(row - (D - H)) < 1e-4))  # first pixel on the block's top
    holes = 0
    u = u_top - 1
    while u >= 0 and row[u] == 0:
        holes += 1
        u -= 1
    assert abs(row[u] - D) < 1e-4  # the band ends on the floor
    width = holes * D / k.fx
    assert width == pytest.approx(b * (D - (D - H)) / (D - H), abs=1.5 * D / k.fx)
    ideal = camera(step(edge, H), SensorModel("none"))
    assert np.count_nonzero(ideal.render_sensor(Pose(DOWN, np.array([0.0, 0.0, D])))[int(k.cy)] == 0) == 0


def test_quantisation_step() -> None:
    d405 = sensor_named("realsense-d405")
    cam = camera(floor(), d405)
    depth = cam.render_sensor(Pose(DOWN, np.array([0.0, 0.0, 0.3])))
    values = depth[depth > 0].astype(np.float64) / d405.depth_unit
    assert np.allclose(values, np.round(values), atol=1e-2)
    assert len(np.unique(np.round(values))) > 3  # noise spreads the plane over several steps


@pytest.mark.parametrize(
    ("name", "inside", "outside"),
    [("realsense-d435", 0.25, 0.15), ("realsense-d405", 0.45, 0.55), ("structured-light", 0.4, 0.9)],
)
def test_range_limits(name: str, inside: float, outside: float) -> None:
    sensor = sensor_named(name)
    cam = camera(floor(), sensor)
    near = cam.render_sensor(Pose(DOWN, np.array([0.0, 0.0, inside])))
    far = cam.render_sensor(Pose(DOWN, np.array([0.0, 0.0, outside])))
    assert (near > 0).mean() > 0.9
    assert not np.any(far > 0)
    assert np.all((near[near > 0] >= sensor.min_range) & (near[near > 0] <= sensor.max_range))


def test_flying_pixels_only_at_discontinuities() -> None:
    pose = Pose(DOWN, np.array([0.0, 0.0, 0.5]))
    clean = camera(step(0.02, 0.1), SensorModel("none")).render_sensor(pose)
    flying = camera(step(0.02, 0.1), SensorModel("fly", flying_probability=1.0)).render_sensor(pose)
    changed = flying != clean
    assert np.count_nonzero(changed) > 50
    assert np.all(discontinuities(clean, 0.01)[changed])
    mixed = flying[changed]
    assert np.all((mixed > 0.4 - 1e-4) & (mixed < 0.5 + 1e-4))  # between the two sides


def test_holes_take_about_their_share() -> None:
    cam = camera(floor(), SensorModel("holes", hole_fraction=0.02))
    depth = cam.render_sensor(Pose(DOWN, np.array([0.0, 0.0, 0.4])))
    lost = float(np.mean(depth == 0))
    assert 0.01 < lost <= 0.02


def test_deterministic_from_the_seed() -> None:
    pose = Pose(DOWN, np.array([0.0, 0.0, 0.4]))
    a = camera(step(0.02, 0.1), SENSORS["realsense-d435"], seed=3).render_sensor(pose)
    b = camera(step(0.02, 0.1), SENSORS["realsense-d435"], seed=3).render_sensor(pose)
    c = camera(step(0.02, 0.1), SENSORS["realsense-d435"], seed=4).render_sensor(pose)
    assert np.array_equal(a, b)
    assert not np.array_equal(a, c)


def test_unknown_sensor_lists_the_names() -> None:
    with pytest.raises(ValueError, match=r"camera\.sensor: unknown sensor 'kinect'; known: ideal, realsense-d435"):
        CameraConfig(sensor="kinect")
    with pytest.raises(ValueError, match="unknown calibration 'perfect'; known: none, typical, poor"):
        CameraConfig(calibration="perfect")


def test_ideal_is_todays_camera() -> None:
    assert SENSORS["ideal"].is_ideal
    assert not SENSORS["realsense-d435"].is_ideal
