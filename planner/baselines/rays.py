"""Candidate rays of the ray-casting baselines and their batched Amanatides–Woo traversal.

This is where ray-casting planners spend their time, so it is written to be a fair
baseline: every ray the method needs, vectorised over all rays of all candidates.

Rays of one candidate view:

- The 8 corners of the bounding box B are projected into the candidate's image;
  the rays go through pixel centres of the axis-aligned pixel rectangle around
  them, clipped to the image (the whole image when a corner is behind the camera).
- Stride: about one voxel at the distance of B, i.e. ``fx * resolution / z_c``
  pixels across and ``fy * resolution / z_c`` down, ``z_c`` the depth of B's
  centre in the camera (candidates look at it); never below one pixel. The
  samples are spread evenly over the rectangle (spacing at most the stride) and
  rounded to pixel centres.
- Rays of the rectangle that miss B are dropped (they are the pixels outside B's
  projected hexagon). Each ray is traversed from where it enters B until it
  leaves B or reaches the first OCCUPIED voxel, which is included (it is hit,
  so it is observed). Voxels outside B are not part of the problem.

Traversal is Amanatides–Woo over the voxel grid (``planner.raycast`` is the
single-ray reference): like it, only positive-length pieces are listed (a ray
grazing an edge does not list the voxels it merely touches) and ties between
axes step x before y before z.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike, NDArray

from planner.types import Intrinsics, Pose


@dataclass(frozen=True, eq=False)
class RayBundle:
    """The rays of several candidate views, concatenated view after view.

    origins: (R, 3) float64 camera centres, world; directions: (R, 3) float64 unit vectors, world;
    pixels: (R, 2) float64 (u, v) pixel centre of each ray; owner: (R,) int64 index of its view;
    t_enter, t_exit: (R,) float64 metres along the ray where it enters / leaves the box (t_enter < t_exit);
    counts: (C,) int64 rays per view (``np.bincount(owner)``).
    """

    origins: NDArray[np.float64]
    directions: NDArray[np.float64]
    pixels: NDArray[np.float64]
    owner: NDArray[np.int64]
    t_enter: NDArray[np.float64]
    t_exit: NDArray[np.float64]
    counts: NDArray[np.int64]

    def __len__(self) -> int:
        return int(self.owner.shape[0])


def box_corners(lower: ArrayLike, upper: ArrayLike) -> NDArray[np.float64]:
    """(8, 3) float64 corners of the axis-aligned box [lower, upper]."""
    lo, hi = np.asarray(lower, dtype=np.float64), np.asarray(upper, dtype=np.float64)
    bits = (np.arange(8)[:, None] >> np.arange(3)) & 1
    return np.where(bits == 1, hi, lo)


def clip_to_box(
    origins: NDArray[np.float64], directions: NDArray[np.float64], lower: ArrayLike, upper: ArrayLike
) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """Slab test: ``(t_enter, t_exit)``, each (R,), of rays ``origins + t directions``, ``t >= 0``, in [lower, upper].

    origins, directions: (R, 3) float64. A ray that misses the box has ``t_exit <= t_enter``.
    """
    lo, hi = np.asarray(lower, dtype=np.float64), np.asarray(upper, dtype=np.float64)
    with np.errstate(divide="ignore", invalid="ignore"):
        t0 = (lo - origins) / directions
        t1 = (hi - origins) / directions
    near, far = np.minimum(t0, t1), np.maximum(t0, t1)
    parallel = directions == 0
    inside = (origins >= lo) & (origins <= hi)
    near = np.where(parallel, np.where(inside, -np.inf, np.inf), near)
    far = np.where(parallel, np.where(inside, np.inf, -np.inf), far)
    return np.maximum(near.max(axis=1), 0.0), far.min(axis=1)


def _samples(first: NDArray[np.int64], last: NDArray[np.int64], stride: NDArray[np.float64]) -> NDArray[np.int64]:
    """(C,) number of samples over the pixel ranges [first, last] (C,) with spacing <= stride (C,); 0 if empty."""
    length = last - first + 1
    return np.where(length > 0, np.ceil(np.maximum(length, 1) / stride), 0).astype(np.int64)


def view_rays(
    poses: Sequence[Pose],
    intrinsics: Intrinsics,
    lower: ArrayLike,
    upper: ArrayLike,
    resolution: float,
    stride_voxels: float = 1.0,
) -> RayBundle:
    """The rays of every view in ``poses`` (``T_world_camera``) through the box [lower, upper] (3,) each.

    See the module docstring for the pixel pattern; ``stride_voxels`` scales the
    stride (1: one voxel at the distance of the box centre).
    """
    if not (np.isfinite(resolution) and resolution > 0):
        raise ValueError(f"resolution: must be > 0, got {resolution!r}")
    if not (np.isfinite(stride_voxels) and stride_voxels > 0):
        raise ValueError(f"stride_voxels: must be > 0, got {stride_voxels!r}")
    lo, hi = np.asarray(lower, dtype=np.float64), np.asarray(upper, dtype=np.float64)
    if lo.shape != (3,) or hi.shape != (3,) or np.any(hi < lo):
        raise ValueError("box: lower and upper must be (3,) with lower <= upper")
    C = len(poses)
    k = intrinsics
    if C == 0:
        z3, z = np.zeros((0, 3)), np.zeros(0)
        return RayBundle(z3, z3, np.zeros((0, 2)), np.zeros(0, np.int64), z, z, np.zeros(0, np.int64))
    Rs = np.stack([p.rotation for p in poses])  # (C, 3, 3) camera -> world
    ts = np.stack([p.translation for p in poses])  # (C, 3)

    corners = np.einsum("cij,cki->ckj", Rs, box_corners(lo, hi)[None] - ts[:, None])  # (C, 8, 3) camera frame
    z = corners[..., 2]
    front = np.all(z > 1e-9, axis=1)
    zs = np.where(front[:, None], z, 1.0)
    u = k.fx * corners[..., 0] / zs + k.cx
    v = k.fy * corners[..., 1] / zs + k.cy
    # pixels whose area [p - 0.5, p + 0.5] overlaps the projected rectangle (whole image if B is partly behind)
    u_first = np.where(front, np.ceil(u.min(axis=1) - 0.5), 0).clip(0, k.width).astype(np.int64)
    u_last = np.where(front, np.floor(u.max(axis=1) + 0.5), k.width - 1).clip(-1, k.width - 1).astype(np.int64)
    v_first = np.where(front, np.ceil(v.min(axis=1) - 0.5), 0).clip(0, k.height).astype(np.int64)
    v_last = np.where(front, np.floor(v.max(axis=1) + 0.5), k.height - 1).clip(-1, k.height - 1).astype(np.int64)

    z_centre = np.einsum("cij,ci->cj", Rs, 0.5 * (lo + hi) - ts)[:, 2]
    with np.errstate(divide="ignore"):
        voxel_px = np.where(z_centre > 1e-9, resolution / z_centre, 0.0)
    stride_u = np.maximum(1.0, stride_voxels * k.fx * voxel_px)
    stride_v = np.maximum(1.0, stride_voxels * k.fy * voxel_px)
    nu, nv = _samples(u_first, u_last, stride_u), _samples(v_first, v_last, stride_v)

    counts = nu * nv
    owner = np.repeat(np.arange(C), counts)
    local = np.arange(owner.size) - np.repeat(np.cumsum(counts) - counts, counts)
    nu_r, nv_r = nu[owner], nv[owner]
    iu, iv = local % nu_r, local // nu_r
    len_u = (u_last - u_first + 1)[owner]
    len_v = (v_last - v_first + 1)[owner]
    pu = (u_first[owner] + np.floor((iu + 0.5) * len_u / nu_r)).astype(np.float64)
    pv = (v_first[owner] + np.floor((iv + 0.5) * len_v / nv_r)).astype(np.float64)

    x = (pu - k.cx) / k.fx
    y = (pv - k.cy) / k.fy
    norm = np.sqrt(x * x + y * y + 1.0)
    R = Rs[owner]
    directions = (R[:, :, 0] * x[:, None] + R[:, :, 1] * y[:, None] + R[:, :, 2]) / norm[:, None]
    origins = ts[owner]
    t_enter, t_exit = clip_to_box(origins, directions, lo, hi)
    hit = t_exit > t_enter
    owner = owner[hit]
    return RayBundle(
        origins[hit],
        directions[hit],
        np.column_stack([pu[hit], pv[hit]]),
        owner,
        t_enter[hit],
        t_exit[hit],
        np.bincount(owner, minlength=C),
    )


EXIT_SLACK = 1e-9
"""Walks stop this many voxel edges before ``t_exit`` (see ``walk_rays``)."""

COMPACT_BELOW = 0.75
"""Ended rays are dropped from the walk's state when fewer than this fraction is alive (else parked)."""

Visitor = Callable[[NDArray[np.int64], NDArray[np.int64]], "NDArray[np.bool_] | None"]
"""``visit(rows (A,), lin (A,))``: rays ``rows`` (ascending, distinct) enter voxels ``lin`` (C-order
linear indices); returns (A,) bool, the rays that end after this voxel, or None (none end)."""


def walk_rays(
    origins: NDArray[np.float64],
    directions: NDArray[np.float64],
    t_enter: NDArray[np.float64],
    t_exit: NDArray[np.float64],
    grid_origin: ArrayLike,
    resolution: float,
    shape: tuple[int, int, int],
    visit: Visitor,
) -> None:
    """Batched Amanatides–Woo: call ``visit`` with the voxels the rays cross for ``t_enter <= t <= t_exit``.

    origins, directions: (R, 3) float64 (directions non-zero; t in their units); t_enter, t_exit:
    (R,) float64, the segments must lie in the grid box ``[grid_origin, grid_origin + shape * resolution]``
    (use ``clip_to_box``). All rays advance together, one voxel per step; ``visit`` is called once
    per step with the rays that entered a voxel, so each ray's voxels arrive in order along it.
    """
    nx, ny, nz = (int(s) for s in shape)
    R = origins.shape[0]
    if R == 0 or nx * ny * nz == 0:
        return
    lo = np.asarray(grid_origin, dtype=np.float64)

    p = origins + t_enter[:, None] * directions
    idx = np.floor((p - lo) / resolution)
    idx = np.where(directions == 0, np.floor((origins - lo) / resolution), idx)
    idx = np.clip(idx, 0, np.array([nx, ny, nz]) - 1).astype(np.int64)
    step = np.sign(directions).astype(np.int64)
    with np.errstate(divide="ignore", invalid="ignore"):
        t_next = (lo + (idx + (step > 0)) * resolution - origins) / directions
        t_delta = resolution / np.abs(directions)
    t_next = np.where(directions == 0, np.inf, t_next)
    # The walk keeps the linear index and steps it by +-stride. A crossing is taken only when it is
    # before t_exit - EXIT_SLACK, so float rounding of the accumulated crossings (~1e-15 m) can never
    # step through the grid's far face; the slack is far below any voxel size.
    t_stop = t_exit - EXIT_SLACK * resolution
    strides = np.array([ny * nz, nz, 1], dtype=np.int64)
    # state, one column per live ray: ints = linear index, signed strides x y z, ray row;
    # floats = next crossing x y z, crossing spacing x y z, t reached, t where the walk stops
    ints = np.concatenate([(idx @ strides)[None], (step * strides).T, np.arange(R)[None]])
    floats = np.concatenate([t_next.T, t_delta.T, t_enter[None], t_stop[None]])

    while ints.shape[1]:
        lin, jx, jy, jz, rows = ints
        tx, ty, tz, dx, dy, dz, t_cur, t_end = floats
        tn = np.minimum(np.minimum(tx, ty), tz)
        mx = tx == tn  # ties: x before y before z
        my = (ty == tn) > mx  # and not mx
        mz = ~(mx | my)
        t_out = np.minimum(tn, t_end)
        seg = t_out > t_cur  # positive-length piece (not merely touching an edge)
        alive = tn < t_end
        if seg.all():
            ended = visit(rows, lin)
            if ended is not None:
                alive &= ~ended
        else:
            ended = visit(rows[seg], lin[seg])
            if ended is not None:
                alive[seg] &= ~ended
        floats[6] = t_out
        lin += np.where(mx, jx, np.where(my, jy, jz))
        np.add(tx, dx, out=tx, where=mx)
        np.add(ty, dy, out=ty, where=my)
        np.add(tz, dz, out=tz, where=mz)
        if not alive.all():
            n_alive = int(np.count_nonzero(alive))
            if n_alive < COMPACT_BELOW * alive.size:
                ints, floats = ints[:, alive], floats[:, alive]
            else:  # park the ended rays: t_end = -inf, so they are never visited again
                floats[7, ~alive] = -np.inf


def traverse_rays(
    origins: NDArray[np.float64],
    directions: NDArray[np.float64],
    t_enter: NDArray[np.float64],
    t_exit: NDArray[np.float64],
    grid_origin: ArrayLike,
    resolution: float,
    shape: tuple[int, int, int],
    stop: NDArray[np.bool_] | None = None,
) -> NDArray[np.int64]:
    """The voxel sequences of ``walk_rays`` as an array: (R, S) int64 C-order linear indices, -1 padded.

    stop: (X, Y, Z) bool or None; a ray ends after the first voxel where it is True (included).
    """
    nx, ny, nz = (int(s) for s in shape)
    R = origins.shape[0]
    out = np.full((R, nx + ny + nz + 1), -1, dtype=np.int64)
    count = np.zeros(R, dtype=np.int64)
    stop_flat = None if stop is None else np.ascontiguousarray(stop, dtype=bool).reshape(-1)

    def record(rows: NDArray[np.int64], lin: NDArray[np.int64]) -> NDArray[np.bool_] | None:
        out[rows, count[rows]] = lin
        count[rows] += 1
        return None if stop_flat is None else stop_flat[lin]

    walk_rays(origins, directions, t_enter, t_exit, grid_origin, resolution, shape, record)
    return out[:, : int(count.max(initial=0))]
