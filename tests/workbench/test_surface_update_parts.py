"""The pieces that make the per-view surface update fast (benchmarks/bench_surface_session.py measures the time):
each gives what its slow form gave. The support filter kept per frame equals the dilation of every seen voxel at
once; the sort-based set operations equal numpy's; the elementwise transform equals ``points_world``; a pickled
surface carries its arrays only; the layer fits its budget in one clustering and the update says its CPU time."""

from __future__ import annotations

import pickle

import numpy as np
import pytest
import trimesh
from scipy import ndimage

from devices.builtins import make_builtin
from devices.config import CameraConfig
from devices.sim import SimulatedCamera
from planner import BoundingBox, DepthFrame, Pose
from workbench.surface import SurfaceConfig, SurfaceIntegrator, layer_mesh
from workbench.surface.export import surface_area
from workbench.surface.integrator import (
    neighbour_offsets,
    sorted_member,
    sorted_unique,
    voxel_indices,
    voxel_keys,
    world_points,
)
from workbench.surface.live import LiveSurface


@pytest.fixture(scope="module")
def frames() -> list[DepthFrame]:
    """Three noise-free frames of the built-in L-block, from three sides."""
    camera = SimulatedCamera(make_builtin("l-block"), CameraConfig())
    centre = np.array([0.0, 0.0, 0.06])
    out = []
    for a in (0.3, 2.4, 4.4):
        eye = centre + 0.5 * np.array([0.8 * np.cos(a), 0.8 * np.sin(a), 0.6])
        pose = Pose.look_at(eye, centre)
        out.append(DepthFrame(camera.render(pose), pose, camera.intrinsics))
    return out


def test_sorted_sets_equal_numpys() -> None:
    rng = np.random.default_rng(3)
    keys = rng.integers(-50, 50, 5_000)
    assert np.array_equal(sorted_unique(keys), np.unique(keys))
    assert len(sorted_unique(np.zeros(0, dtype=np.int64))) == 0
    table = np.unique(rng.integers(-50, 50, 40))
    assert np.array_equal(sorted_member(keys, table), np.isin(keys, table))
    assert not sorted_member(keys, np.zeros(0, dtype=np.int64)).any()


def test_neighbour_offsets_move_the_packed_indices() -> None:
    ijk = np.array([[5, -7, 0], [-(2**19), 2**19, 3]])
    moved = (voxel_keys(ijk)[:, None] + neighbour_offsets(2)[None, :]).ravel()
    d = np.arange(-2, 3)
    steps = np.stack(np.meshgrid(d, d, d, indexing="ij"), axis=-1).reshape(-1, 3)
    expected = voxel_keys((ijk[:, None, :] + steps[None, :, :]).reshape(-1, 3))
    assert np.array_equal(moved, expected) and len(neighbour_offsets(1)) == 27


def test_world_points_equal_the_frames_own(frames: list[DepthFrame]) -> None:
    for frame in frames:
        np.testing.assert_allclose(world_points(frame), frame.points_world, rtol=0, atol=1e-12)


@pytest.mark.parametrize("r", [1, 2])
def test_the_support_kept_per_frame_equals_one_dilation_of_all(frames: list[DepthFrame], r: int) -> None:
    config = SurfaceConfig(support_voxels=r)
    box = BoundingBox(np.array([-0.15, -0.15, 0.0]), np.array([0.15, 0.15, 0.25]))  # given: the same for every frame
    integrator = SurfaceIntegrator(config, box)
    for frame in frames:
        integrator.integrate(frame)
    cloud = np.concatenate([world_points(f) for f in frames])
    m = config.box_margin
    seen = cloud[np.all((cloud >= box.lower - m) & (cloud <= box.upper + m), axis=1)]
    seen = seen[seen[:, 2] >= config.plate_clearance]
    ijk = np.unique(voxel_indices(seen, config.voxel_size), axis=0)
    origin = ijk.min(axis=0) - r - 1
    grid = np.zeros(tuple(ijk.max(axis=0) - origin + r + 2), dtype=bool)
    grid[tuple((ijk - origin).T)] = True
    grid = ndimage.binary_dilation(grid, structure=np.ones((3, 3, 3), dtype=bool), iterations=r)
    expected = np.sort(voxel_keys(np.argwhere(grid) + origin))
    assert np.array_equal(integrator._supported_keys, expected)
    surface = integrator.mesh()
    assert integrator._supported(surface.vertices).all()


def test_a_pickled_surface_is_its_arrays(frames: list[DepthFrame]) -> None:
    integrator = SurfaceIntegrator()
    for frame in frames:
        integrator.integrate(frame)
    surface = integrator.mesh()
    bare = len(pickle.dumps(surface))
    assert surface.area > 0  # builds and caches the trimesh
    data = pickle.dumps(surface)
    assert len(data) == bare < 30 * (len(surface.vertices) + len(surface.faces))
    back = pickle.loads(data)
    assert back == surface and not back.vertices.flags.writeable
    assert surface_area(surface) == pytest.approx(trimesh.Trimesh(surface.vertices, surface.faces).area)


def test_the_live_update_says_its_cpu_time_and_fits_the_layer(frames: list[DepthFrame]) -> None:
    live = LiveSurface(max_triangles=3_000)
    for frame in frames:
        update = live.add(frame, frame.T_world_camera)
    assert update.error is None and update.mesh is not None and update.layer is not None
    assert update.cpu_seconds > 0 and update.seconds > 0
    assert update.mesh.triangles > 3_000 >= update.layer.triangles > 0.5 * 3_000  # near the budget, not far below
    assert layer_mesh(update.mesh, update.mesh.triangles) is update.mesh  # within its budget: as it is


def test_a_real_sensor_fuses_with_a_shorter_truncation() -> None:
    from devices.config import CameraConfig
    from workbench.surface import surface_config_for
    from workbench.surface.config import REAL_SENSOR_TRUNCATION_VOXELS

    ideal = surface_config_for(CameraConfig())
    assert ideal == SurfaceConfig()  # the ideal camera: the defaults, as measured
    assert surface_config_for(CameraConfig(calibration="typical")) == SurfaceConfig()  # a pose error is not noise
    base = SurfaceConfig(voxel_size=0.003)
    for camera in (CameraConfig(sensor="realsense-d435"), CameraConfig(depth_noise_std=0.001)):
        real = surface_config_for(camera, base)
        assert real.truncation_voxels == REAL_SENSOR_TRUNCATION_VOXELS < ideal.truncation_voxels
        assert real.voxel_size == 0.003  # the rest of the base kept
