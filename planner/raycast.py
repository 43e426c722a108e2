"""Amanatides–Woo voxel traversal: the exact reference for integrating a depth frame.

A grid is given by ``lower`` (3,) (world position of the lower corner of voxel
(0, 0, 0)), ``resolution`` (voxel edge, metres) and ``shape`` (3,) (voxel counts);
voxel ``(i, j, k)`` is the half-open cube ``lower + [i, i+1) x [j, j+1) x [k, k+1) * resolution``.

Rays are ``origin + t * direction`` with ``t >= 0``. Directions need not be unit
vectors: the depth integration uses pixel rays whose camera-z component is 1, so
``t`` *is* the planar z-depth and the hit of pixel ``(u, v)`` is at ``t = depth[v, u]``.

Classification of one ray's voxels (paper §III-C): a voxel the ray leaves at or
before the hit (``t_out <= t_hit + EMPTY_EPS``) is passed through: EMPTY.
Every later voxel, including the one that contains the hit, is UNKNOWN (the one
containing the hit becomes OCCUPIED only through the frame's points). A ray with
no return (``t_hit = inf``) marks every voxel it crosses EMPTY.
Within one frame a voxel crossed by several rays is UNKNOWN if any ray calls it
UNKNOWN (conservative: EMPTY is final, so a voxel is only carved when every ray
that touched it passed all the way through it).

This is the exact reference; ``planner.voxel_map.observe_projective`` is the fast
default that samples the same rule at each voxel's centre and corners.
"""

from __future__ import annotations

import numpy as np
from numpy.typing import ArrayLike, NDArray

from planner.types import DepthFrame, VoxelClass
from planner.validate import checked_array

EMPTY_EPS = 1e-6
"""Metres of slack in favour of EMPTY when a voxel's exit depth equals the hit depth
(float32 depth rounding; surfaces lying exactly on a lattice plane, like the plate at z = 0)."""


def _grid(
    lower: ArrayLike, resolution: float, shape: ArrayLike
) -> tuple[NDArray[np.float64], float, NDArray[np.int64]]:
    lo = checked_array("lower", lower, (3,))
    if not (np.isfinite(resolution) and resolution > 0):
        raise ValueError(f"resolution: must be > 0, got {resolution!r}")
    shp = np.asarray(shape)
    if shp.shape != (3,) or not np.all(shp == np.round(shp)) or np.any(shp < 0):
        raise ValueError(f"shape: expected 3 non-negative integers, got {shape!r}")
    return lo, float(resolution), shp.astype(np.int64)


def _slab(
    origin: NDArray[np.float64], dirs: NDArray[np.float64], lo: NDArray[np.float64], hi: NDArray[np.float64]
) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """Entry/exit parameters (R,), (R,) of rays ``origin + t dirs[r]`` through the box [lo, hi] (t unbounded)."""
    with np.errstate(divide="ignore", invalid="ignore"):
        t0 = (lo - origin) / dirs
        t1 = (hi - origin) / dirs
    near = np.minimum(t0, t1)
    far = np.maximum(t0, t1)
    # An axis with zero direction: the ray is inside the slab (any t) or outside (no t).
    parallel = dirs == 0
    inside = (origin >= lo) & (origin < hi)
    near = np.where(parallel, np.where(inside, -np.inf, np.inf), near)
    far = np.where(parallel, np.where(inside, np.inf, -np.inf), far)
    return near.max(axis=-1), far.min(axis=-1)


def _start(
    origin: NDArray[np.float64],
    dirs: NDArray[np.float64],
    t_enter: NDArray[np.float64],
    lower: NDArray[np.float64],
    res: float,
    shape: NDArray[np.int64],
) -> tuple[NDArray[np.int64], NDArray[np.int64], NDArray[np.float64]]:
    """First voxel (R, 3), steps (R, 3) and next boundary crossings t_next (R, 3) of each ray."""
    p = origin + t_enter[:, None] * dirs
    idx = np.floor((p - lower) / res).astype(np.int64)
    on_axis = np.floor((origin - lower) / res).astype(np.int64)
    idx = np.where(dirs == 0, on_axis, idx)  # exact for axes the ray does not move along
    idx = np.clip(idx, 0, shape - 1)
    step = np.sign(dirs).astype(np.int64)
    return idx, step, _next_crossing(origin, dirs, idx, step, lower, res)


def _next_crossing(
    origin: NDArray[np.float64],
    dirs: NDArray[np.float64],
    idx: NDArray[np.int64],
    step: NDArray[np.int64],
    lower: NDArray[np.float64],
    res: float,
) -> NDArray[np.float64]:
    """t where each ray leaves voxel ``idx`` through the face it is heading to (recomputed, no drift)."""
    boundary = lower + (idx + (step > 0)) * res
    with np.errstate(divide="ignore", invalid="ignore"):
        t = (boundary - origin) / dirs
    return np.where(dirs == 0, np.inf, t)


def traverse_with_t(
    origin: ArrayLike,
    direction: ArrayLike,
    t_max: float,
    lower: ArrayLike,
    resolution: float,
    shape: ArrayLike,
) -> tuple[NDArray[np.int64], NDArray[np.float64], NDArray[np.float64]]:
    """Voxels of the segment ``origin + t direction``, ``0 <= t <= t_max``, in order, with entry/exit ``t``.

    origin, direction: (3,) float64 world; t_max: > 0 (may be ``inf``).
    Returns ``(indices (K, 3) int64, t_in (K,), t_out (K,))``; only voxels of the
    grid and only positive-length pieces (a ray grazing an edge does not list the
    voxels it merely touches).
    """
    lo, res, shp = _grid(lower, resolution, shape)
    o = checked_array("origin", origin, (3,))
    d = checked_array("direction", direction, (3,))
    if not np.any(d != 0):
        raise ValueError("direction: must be non-zero")
    if not (t_max > 0):
        raise ValueError(f"t_max: must be > 0, got {t_max!r}")
    empty = (np.zeros((0, 3), np.int64), np.zeros(0), np.zeros(0))
    if np.any(shp == 0):
        return empty
    t_near, t_far = _slab(o, d[None, :], lo, lo + shp * res)
    t_cur, t_exit = max(float(t_near[0]), 0.0), min(float(t_far[0]), float(t_max))
    if not t_cur < t_exit:
        return empty
    idx_a, step_a, t_next_a = _start(o, d[None, :], np.array([t_cur]), lo, res, shp)
    idx, step, t_next = idx_a[0], step_a[0], t_next_a[0]
    out_idx: list[NDArray[np.int64]] = []
    t_in: list[float] = []
    t_out: list[float] = []
    while True:
        a = int(np.argmin(t_next))
        t_end = min(float(t_next[a]), t_exit)
        if t_end > t_cur:
            out_idx.append(idx.copy())
            t_in.append(t_cur)
            t_out.append(t_end)
        if t_next[a] >= t_exit:
            break
        t_cur = t_end
        idx[a] += step[a]
        if not 0 <= idx[a] < shp[a]:
            break
        t_next[a] = _next_crossing(o[a], d[a], idx[a], step[a], lo[a], res)
    return np.array(out_idx, dtype=np.int64).reshape(-1, 3), np.array(t_in), np.array(t_out)


def traverse(
    origin: ArrayLike,
    direction: ArrayLike,
    t_max: float,
    lower: ArrayLike,
    resolution: float,
    shape: ArrayLike,
) -> NDArray[np.int64]:
    """(K, 3) int64 voxel indices crossed by ``origin + t direction``, ``0 <= t <= t_max``, in order along the ray.

    Exact Amanatides–Woo traversal clipped to the grid (see ``traverse_with_t``).
    """
    return traverse_with_t(origin, direction, t_max, lower, resolution, shape)[0]


def ray_observations(
    origin: ArrayLike,
    directions: ArrayLike,
    t_hit: ArrayLike,
    lower: ArrayLike,
    resolution: float,
    shape: ArrayLike,
) -> tuple[NDArray[np.bool_], NDArray[np.bool_]]:
    """Batched traversal of many rays from one origin; which voxels some ray called EMPTY / UNKNOWN.

    origin: (3,) world; directions: (R, 3) (non-zero); t_hit: (R,) ray parameter of
    the hit, ``inf`` for no return. Every ray is traversed through the whole grid.
    Returns ``(empty_seen, unknown_seen)``, each (X, Y, Z) bool: some ray left the
    voxel at or before its hit / some ray was inside the voxel after its hit.
    """
    lo, res, shp = _grid(lower, resolution, shape)
    o = checked_array("origin", origin, (3,))
    dirs = checked_array("directions", directions, (None, 3))
    hit = np.array(t_hit, dtype=np.float64).reshape(-1)
    if hit.shape[0] != dirs.shape[0] or np.any(np.isnan(hit)):
        raise ValueError(f"t_hit: expected ({dirs.shape[0]},) numbers, got shape {hit.shape}")
    if np.any(~np.any(dirs != 0, axis=1)):
        raise ValueError("directions: zero direction vector")
    n_vox = int(np.prod(shp))
    empty_seen = np.zeros(n_vox, dtype=bool)
    unknown_seen = np.zeros(n_vox, dtype=bool)
    if n_vox == 0 or dirs.shape[0] == 0:
        return empty_seen.reshape(tuple(shp)), unknown_seen.reshape(tuple(shp))
    t_near, t_far = _slab(o, dirs, lo, lo + shp * res)
    t_cur = np.maximum(t_near, 0.0)
    keep = t_cur < t_far
    dirs, hit, t_cur, t_exit = dirs[keep], hit[keep] + EMPTY_EPS, t_cur[keep], t_far[keep]
    idx, step, t_next = _start(o, dirs, t_cur, lo, res, shp)
    strides = np.array([shp[1] * shp[2], shp[2], 1], dtype=np.int64)
    while dirs.shape[0]:
        rows = np.arange(dirs.shape[0])
        a = np.argmin(t_next, axis=1)
        tn = t_next[rows, a]
        t_end = np.minimum(tn, t_exit)
        seg = t_end > t_cur
        flat = idx @ strides
        is_empty = t_end <= hit
        empty_seen[flat[seg & is_empty]] = True
        unknown_seen[flat[seg & ~is_empty]] = True
        # advance along axis a
        idx[rows, a] += step[rows, a]
        ia = idx[rows, a]
        alive = (tn < t_exit) & (ia >= 0) & (ia < shp[a])
        t_cur = t_end
        t_next[rows, a] = _next_crossing(o[a], dirs[rows, a], ia, step[rows, a], lo[a], res)
        if not np.all(alive):
            dirs, hit, t_cur, t_exit = dirs[alive], hit[alive], t_cur[alive], t_exit[alive]
            idx, step, t_next = idx[alive], step[alive], t_next[alive]
    return empty_seen.reshape(tuple(shp)), unknown_seen.reshape(tuple(shp))


def pixel_rays(
    frame: DepthFrame, stride: int = 1
) -> tuple[NDArray[np.float64], NDArray[np.float64], NDArray[np.float64]]:
    """Rays through every ``stride``-th pixel centre: ``(origin (3,), directions (R, 3), t_hit (R,))``.

    Directions are world vectors whose camera-z component is 1, so ``t`` is the planar
    depth; ``t_hit`` is the depth, ``inf`` where the pixel has no return.
    """
    if int(stride) != stride or stride < 1:
        raise ValueError(f"stride: must be an integer >= 1, got {stride!r}")
    k = frame.intrinsics
    vs, us = np.meshgrid(np.arange(0, k.height, stride), np.arange(0, k.width, stride), indexing="ij")
    u, v = us.ravel(), vs.ravel()
    dirs_cam = np.column_stack([(u - k.cx) / k.fx, (v - k.cy) / k.fy, np.ones(u.size)])
    depth = frame.depth[v, u].astype(np.float64)
    t_hit = np.where(depth > 0, depth, np.inf)
    T = frame.T_world_camera
    return T.translation.copy(), dirs_cam @ T.rotation.T, t_hit


def observe_raycast(
    frame: DepthFrame, lower: ArrayLike, resolution: float, shape: ArrayLike, stride: int = 1
) -> NDArray[np.uint8]:
    """What one frame says about each voxel, by casting one ray per ``stride``-th pixel.

    Returns (X, Y, Z) uint8: ``VoxelClass.EMPTY``, ``VoxelClass.UNKNOWN`` or 0 (no ray
    touched the voxel: outside the frustum, or between sampled rays).
    """
    origin, dirs, t_hit = pixel_rays(frame, stride)
    empty_seen, unknown_seen = ray_observations(origin, dirs, t_hit, lower, resolution, shape)
    obs = np.zeros(empty_seen.shape, dtype=np.uint8)
    obs[empty_seen] = VoxelClass.EMPTY
    obs[unknown_seen] = VoxelClass.UNKNOWN
    return obs
