"""Amanatides–Woo traversal: hand-computed sequences, exactness against the ray equation, batched == single."""

from __future__ import annotations

import numpy as np
import pytest

from planner.raycast import EMPTY_EPS, observe_raycast, pixel_rays, ray_observations, traverse, traverse_with_t
from planner.types import DepthFrame, Intrinsics, Pose, VoxelClass

UNIT = ([0.0, 0.0, 0.0], 1.0)


def test_axis_ray_through_a_row() -> None:
    idx, t_in, t_out = traverse_with_t([-1.0, 0.5, 0.5], [1.0, 0.0, 0.0], np.inf, *UNIT, (4, 1, 1))
    np.testing.assert_array_equal(idx, [[0, 0, 0], [1, 0, 0], [2, 0, 0], [3, 0, 0]])
    np.testing.assert_allclose(t_in, [1, 2, 3, 4])
    np.testing.assert_allclose(t_out, [2, 3, 4, 5])


def test_t_max_stops_inside_a_voxel() -> None:
    idx, _, t_out = traverse_with_t([-1.0, 0.5, 0.5], [1.0, 0.0, 0.0], 2.5, *UNIT, (4, 1, 1))
    np.testing.assert_array_equal(idx, [[0, 0, 0], [1, 0, 0]])
    assert t_out[-1] == 2.5


def test_diagonal_ray_in_a_plane() -> None:
    # x crossings at t = 0.5, 1.5, 2.5; y crossings at 0.75, 1.75, 2.75
    idx = traverse([0.5, 0.25, 0.5], [1.0, 1.0, 0.0], np.inf, *UNIT, (3, 3, 1))
    np.testing.assert_array_equal(idx[:, :2], [[0, 0], [1, 0], [1, 1], [2, 1], [2, 2]])


def test_negative_direction_scaled_grid() -> None:
    # lower (0.1, 0.2, 0.3), 0.05 voxels: the ray enters at x = 0.25 (voxel 2) and walks down to voxel 0
    idx, t_in, _ = traverse_with_t([0.4, 0.21, 0.31], [-2.0, 0.0, 0.0], np.inf, [0.1, 0.2, 0.3], 0.05, (3, 1, 1))
    np.testing.assert_array_equal(idx[:, 0], [2, 1, 0])
    np.testing.assert_allclose(t_in, [0.075, 0.1, 0.125])  # direction has length 2


def test_misses_and_errors() -> None:
    assert traverse([-1.0, 2.0, 0.5], [1.0, 0.0, 0.0], np.inf, *UNIT, (4, 1, 1)).shape == (0, 3)
    assert traverse([-1.0, 0.5, 0.5], [-1.0, 0.0, 0.0], np.inf, *UNIT, (4, 1, 1)).shape == (0, 3)  # points away
    with pytest.raises(ValueError, match="direction"):
        traverse([0.0, 0.0, 0.0], [0.0, 0.0, 0.0], 1.0, *UNIT, (2, 2, 2))
    with pytest.raises(ValueError, match="shape"):
        traverse([0.0, 0.0, 0.0], [1.0, 0.0, 0.0], 1.0, *UNIT, (2, 2))
    with pytest.raises(ValueError, match="origin"):
        traverse([np.nan, 0.0, 0.0], [1.0, 0.0, 0.0], 1.0, *UNIT, (2, 2, 2))


@pytest.mark.parametrize("seed", range(20))
def test_random_rays_are_exact(seed: int) -> None:
    """Pieces tile the clipped segment, each midpoint lies in its voxel, consecutive voxels share a face."""
    rng = np.random.default_rng(seed)
    lower, res, shape = rng.uniform(-1, 1, 3), 0.1, rng.integers(3, 9, 3)
    origin = lower + rng.uniform(-0.5, 1.5, 3) * shape * res
    direction = lower + rng.uniform(0, 1, 3) * shape * res - origin  # aimed at a point of the grid (t = 1)
    if seed % 4 == 0:
        direction[seed % 3] = 0.0  # axis-parallel component
    t_max = float(rng.uniform(0.3, 2.0))
    idx, t_in, t_out = traverse_with_t(origin, direction, t_max, lower, res, shape)
    # reference clip of the segment to the grid box
    hi = lower + shape * res
    with np.errstate(divide="ignore"):
        t0, t1 = (lower - origin) / direction, (hi - origin) / direction
    par = direction == 0
    near = np.where(par, -np.inf, np.minimum(t0, t1)).max()
    far = np.where(par, np.inf, np.maximum(t0, t1)).min()
    inside_par = np.all((origin[par] >= lower[par]) & (origin[par] < hi[par]))
    t_a, t_b = max(near, 0.0), min(far, t_max)
    if not (t_a < t_b and inside_par):
        assert idx.shape == (0, 3)
        return
    assert len(idx) >= 1
    assert t_in[0] == pytest.approx(t_a, abs=1e-12) and t_out[-1] == pytest.approx(t_b, abs=1e-12)
    np.testing.assert_allclose(t_in[1:], t_out[:-1], atol=1e-12)
    assert np.all(t_out > t_in)
    mid = origin + 0.5 * (t_in + t_out)[:, None] * direction
    np.testing.assert_array_equal(np.floor((mid - lower) / res).astype(int), idx)
    steps = np.abs(np.diff(idx, axis=0))
    assert np.all(steps.max(axis=1) == 1)  # moves one voxel at a time (edge/corner crossings
    assert np.all(np.all((idx >= 0) & (idx < shape), axis=1))  # may skip zero-length pieces)


@pytest.mark.parametrize("seed", range(3))
def test_batched_observations_equal_single_ray_traversal(seed: int) -> None:
    rng = np.random.default_rng(seed)
    lower, res, shape = np.array([-0.1, -0.1, 0.2]), 0.02, (10, 9, 8)
    origin = np.array([0.003, -0.002, 0.0])
    dirs = np.column_stack([rng.uniform(-0.3, 0.3, 300), rng.uniform(-0.3, 0.3, 300), np.ones(300)])
    t_hit = np.where(rng.random(300) < 0.2, np.inf, rng.uniform(0.15, 0.4, 300))
    empty, unknown = ray_observations(origin, dirs, t_hit, lower, res, shape)
    exp_e, exp_u = np.zeros(shape, bool), np.zeros(shape, bool)
    for d, th in zip(dirs, t_hit, strict=True):
        idx, _, t_out = traverse_with_t(origin, d, np.inf, lower, res, shape)
        before = t_out <= th + EMPTY_EPS
        exp_e[tuple(idx[before].T)] = True
        exp_u[tuple(idx[~before].T)] = True
    np.testing.assert_array_equal(empty, exp_e)
    np.testing.assert_array_equal(unknown, exp_u)
    assert empty.any() and unknown.any()


def test_pixel_rays_have_unit_depth_and_hit_the_backprojected_points() -> None:
    k = Intrinsics(8, 6, 10.0, 10.0, 3.5, 2.5)
    T = Pose.look_at([0.3, -0.2, 0.4], [0.0, 0.0, 0.0])
    depth = np.full((6, 8), 0.5, np.float32)
    depth[0, 0] = 0.0
    frame = DepthFrame(depth, T, k)
    origin, dirs, t_hit = pixel_rays(frame)
    np.testing.assert_allclose((dirs @ T.rotation)[:, 2], 1.0)
    assert np.isinf(t_hit[0]) and np.all(t_hit[1:] == 0.5)
    np.testing.assert_allclose(origin + t_hit[1:, None] * dirs[1:], frame.points_world, atol=1e-12)
    assert pixel_rays(frame, stride=2)[1].shape == (12, 3)
    with pytest.raises(ValueError, match="stride"):
        pixel_rays(frame, stride=0)


def test_wall_seen_head_on() -> None:
    """Camera at z=0 looking +z at a wall at depth 0.255: voxels z<0.25 empty, the wall voxel and beyond unknown."""
    k = Intrinsics(40, 40, 40.0, 40.0, 19.5, 19.5)
    T = Pose.look_at([0.0, 0.0, 0.0], [0.0, 0.0, 1.0], up=[0.0, -1.0, 0.0])  # camera axes = world axes
    np.testing.assert_allclose(T.rotation, np.eye(3), atol=1e-12)
    frame = DepthFrame(np.full((40, 40), 0.255, np.float32), T, k)
    obs = observe_raycast(frame, [-0.05, -0.05, 0.2], 0.01, (10, 10, 10))
    assert np.all(obs[:, :, :5] == VoxelClass.EMPTY)  # z in [0.2, 0.25)
    assert np.all(obs[:, :, 5:] == VoxelClass.UNKNOWN)  # the voxel holding the hit, and behind it
    obs_sparse = observe_raycast(frame, [-0.05, -0.05, 0.2], 0.01, (10, 10, 10), stride=8)
    touched = obs_sparse > 0
    np.testing.assert_array_equal(obs_sparse[touched], obs[touched])
    assert 0 < np.count_nonzero(~touched) < obs.size  # sparse rays leave some voxels untouched
