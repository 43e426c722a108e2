"""The plate as each frame's registered pose puts it: a registration that turns a frame about a direction the object
hardly constrains (a cylinder lying on the plate: its axis) tilts the plate seen through that pose; the surface must
neither grow the object's box over the tilted plate nor fuse it as surface."""

from __future__ import annotations

import math

import numpy as np
import pytest
import trimesh

from devices.config import CameraConfig
from devices.sim import SimulatedCamera
from planner import BoundingBox, DepthFrame, Pose
from workbench.surface import SurfaceConfig, SurfaceIntegrator, frame_plate_plane, surface_accuracy
from workbench.surface.integrator import world_points

RADIUS, LENGTH = 0.03, 0.2
"""The lying cylinder: its axis along world y at height RADIUS, resting on the plate (a screwdriver's handle)."""
TURN_DEG = 5.0
"""The registration's turn about the cylinder's axis: the object's points still fit, the plate 0.2 m from the axis
rises 17 mm."""
SCORE_POINTS = 20_000
"""Points sampled on a surface to score it (the default 100 000 takes seconds; 2 mm apart is plenty here)."""


def lying_cylinder() -> trimesh.Trimesh:
    mesh = trimesh.creation.cylinder(radius=RADIUS, height=LENGTH, sections=64)  # axis along z
    mesh.apply_transform(trimesh.transformations.rotation_matrix(math.pi / 2, (1.0, 0.0, 0.0)))  # axis along y
    mesh.apply_translation((0.0, 0.0, RADIUS))
    return mesh


def distance_to_cylinder(points: np.ndarray) -> np.ndarray:
    """(N,) distance of ``points`` (N, 3) to the lying cylinder's surface (its side and its two end caps)."""
    radial = np.hypot(points[:, 0], points[:, 2] - RADIUS) - RADIUS
    axial = np.abs(points[:, 1]) - LENGTH / 2
    outside = np.hypot(np.maximum(radial, 0.0), np.maximum(axial, 0.0))
    return np.where((radial <= 0) & (axial <= 0), -np.maximum(radial, axial), outside)


def turned_about_axis(pose: Pose, degrees: float) -> Pose:
    """``pose`` moved by a turn of ``degrees`` about the cylinder's axis (world y through (0, 0, RADIUS)): the
    correction ICP may find for a frame of a body of revolution, which maps the object onto itself."""
    a = math.radians(degrees)
    R = np.array([[math.cos(a), 0.0, math.sin(a)], [0.0, 1.0, 0.0], [-math.sin(a), 0.0, math.cos(a)]])
    centre = np.array([0.0, 0.0, RADIUS])
    correction = Pose(R, centre - R @ centre)
    return correction @ pose


def view(camera: SimulatedCamera, azimuth_deg: float, elevation_deg: float) -> DepthFrame:
    """A noise-free frame from 0.5 m away, looking at the cylinder's middle, with its true pose."""
    centre = np.array([0.0, 0.0, RADIUS])
    a, e = math.radians(azimuth_deg), math.radians(elevation_deg)
    eye = centre + 0.5 * np.array([math.cos(e) * math.cos(a), math.cos(e) * math.sin(a), math.sin(e)])
    pose = Pose.look_at(eye, centre)
    return DepthFrame(camera.render(pose), pose, camera.intrinsics)


@pytest.fixture(scope="module")
def cylinder() -> trimesh.Trimesh:
    return lying_cylinder()


@pytest.fixture(scope="module")
def frames(cylinder: trimesh.Trimesh) -> tuple[list[DepthFrame], DepthFrame]:
    """(three high views at their true poses, a low view from the side at the pose a registration turned)."""
    camera = SimulatedCamera(cylinder, CameraConfig())
    high = [view(camera, azimuth, 45.0) for azimuth in (0.0, 120.0, 240.0)]
    low = view(camera, 60.0, 12.0)
    return high, low.with_pose(turned_about_axis(low.T_world_camera, TURN_DEG))


def test_a_low_view_turned_by_the_registration_keeps_the_surface_on_the_object(cylinder, frames) -> None:
    high, low = frames
    tilted = world_points(low)
    lifted = tilted[(tilted[:, 2] >= SurfaceConfig().plate_clearance) & (np.abs(tilted[:, 0]) > 0.1)]
    assert len(lifted) > 1000  # the mechanism: the plate far from the axis rises above the plate cut
    integrator = SurfaceIntegrator()
    for frame in high:
        integrator.integrate(frame)
    before = surface_accuracy(integrator.mesh(), cylinder, n_points=SCORE_POINTS)
    integrator.integrate(low)
    box = integrator.box
    assert box is not None
    # the object's box stays the cylinder's (x within +-RADIUS, y within +-LENGTH/2), not the plate's 0.4 m
    assert np.all(box.upper[:2] <= [RADIUS + 0.005, LENGTH / 2 + 0.005])
    assert np.all(box.lower[:2] >= [-RADIUS - 0.005, -LENGTH / 2 - 0.005])
    surface = integrator.mesh()
    assert np.quantile(distance_to_cylinder(surface.vertices), 0.99) <= 0.005  # no sheet of plate around it
    after = surface_accuracy(surface, cylinder, n_points=SCORE_POINTS)
    assert after.precision_5mm >= 0.97
    assert after.fscore_5mm >= before.fscore_5mm  # the low view adds to the surface, it does not break it


def test_the_plate_of_a_turned_frame_is_found_and_a_right_frame_keeps_z_zero(cylinder, frames) -> None:
    high, low = frames
    config = SurfaceConfig()
    box = BoundingBox(cylinder.bounds[0], cylinder.bounds[1])
    for frame in high:  # true poses: exactly z = 0, so their surface is the one without the fit
        assert np.array_equal(frame_plate_plane(world_points(frame), config, box), np.zeros(3))
    a, b, c = frame_plate_plane(world_points(low), config, box)
    assert math.hypot(a, b) == pytest.approx(math.tan(math.radians(TURN_DEG)), rel=0.05)
    assert abs(b) < 0.1 * abs(a)  # tilted along x: the turn was about y
    assert abs(c) < 0.002
    assert np.array_equal(frame_plate_plane(world_points(low), config, box), [a, b, c])  # the same frame, plane


def test_no_plate_in_view_is_z_zero() -> None:
    config = SurfaceConfig()
    assert np.array_equal(frame_plate_plane(np.zeros((0, 3)), config), np.zeros(3))
    rng = np.random.default_rng(1)
    wall = np.column_stack([np.full(2000, 0.05), rng.uniform(-0.1, 0.1, 2000), rng.uniform(0.0, 0.03, 2000)])
    assert np.array_equal(frame_plate_plane(wall, config), np.zeros(3))  # a vertical face is no plate


def test_the_objects_own_low_face_is_no_plate_once_its_box_is_known() -> None:
    """From a very low view the plate may be a thin strip and a low face of the object a wide patch near z = 0:
    only the points outside the object's footprint are the plate's candidates."""
    config = SurfaceConfig()
    rng = np.random.default_rng(2)
    xy = rng.uniform(-0.05, 0.05, (5000, 2))
    face = np.column_stack([xy, 0.005 + 0.15 * xy[:, 0]])  # the object's base, sloping 8.5 degrees
    strip = np.column_stack([rng.uniform(0.1, 0.2, 800), rng.uniform(-0.02, 0.02, 800), np.zeros(800)])
    points = np.vstack([face, strip])
    assert frame_plate_plane(points, config)[0] == pytest.approx(0.15)  # without the box: the face wins
    box = BoundingBox(np.array([-0.05, -0.05, 0.0]), np.array([0.05, 0.05, 0.05]))
    assert np.array_equal(frame_plate_plane(points, config, box), np.zeros(3))
