"""Ellipsoids rasterised into small depth images, one per candidate view (the ``projection-zbuffer`` evaluator).

The paper orders ellipsoids by the depth of their centres and weighs them by ``0.5^rank``
(§III-E); it never asks whether an ellipsoid actually hides another. Here every ellipsoid
is drawn into a coarse ``w x h`` image of each candidate camera (default 40 x 30 for a
640 x 480 camera: one raster pixel per 16 x 16 camera pixels) with its true per-pixel depth,
so visibility is decided per pixel by a z-buffer. Still ellipsoids, not voxels: the cost
grows with the pixels the ellipses cover, never with the voxel count.

Raster pixel ``(i, j)``, ``i = 0..w-1``, ``j = 0..h-1``, stands for the camera pixels of
its block; its ray goes through the block's centre, camera pixel
``u = (i + 0.5) W / w - 0.5``, ``v = (j + 0.5) H / h - 0.5``, i.e. the normalised ray
``d = (x, y, 1)`` with ``x = (u - cx) / fx``, ``y = (v - cy) / fy``.

Per camera x ellipsoid pair (camera frame: centre ``m = R^T (c - t)``, shape
``A' = R^T A R``, ``g = m^T A' m - 1``) the ray ``s d``, ``s > 0``, meets the ellipsoid
where ``a s^2 - 2 b s + g = 0`` with ``a = d^T A' d``, ``b = d^T A' m``: it hits iff
``b^2 >= a g`` and ``b > 0`` (camera outside, ``g > 0``), first at depth
``z = s = (b - sqrt(b^2 - a g)) / a`` (``d_z = 1``, so ``s`` is the planar depth).

Only the pixels of each pair's projected bounding box are tested. The box comes from the
two planes ``x = k z`` tangent to the ellipsoid (support function ``n.m +- sqrt(n^T N n)``,
``N = A'^-1``): ``k`` solves ``D k^2 - 2 (m_x m_z - N_xz) k + (m_x^2 - N_xx) = 0`` with
``D = m_z^2 - N_zz > 0`` (the ellipsoid lies in front of the camera); the same for y.
An ellipsoid that crosses the plane ``z = 0`` (``D <= 0``, camera outside) is tested over
the whole image; one behind the camera is skipped; one that contains the camera covers
every pixel at depth 0.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from planner.types import Ellipsoid, Intrinsics, Pose


@dataclass(frozen=True, eq=False)
class Fragments:
    """Every (camera, ellipsoid, raster pixel) hit: F fragments of C cameras, E ellipsoids, a w x h raster.

    camera: (F,) int64 camera index; ellipsoid: (F,) int64 ellipsoid index;
    pixel: (F,) int64 raster pixel ``j * w + i``; depth: (F,) float64 planar depth of the
    first hit along the pixel's ray, metres (0 when the camera is inside the ellipsoid);
    inside: (C, E) bool, the camera is inside the ellipsoid;
    center_depth: (C, E) float64 camera-frame z of every ellipsoid centre.
    """

    width: int
    height: int
    n_cameras: int
    n_ellipsoids: int
    camera: NDArray[np.int64]
    ellipsoid: NDArray[np.int64]
    pixel: NDArray[np.int64]
    depth: NDArray[np.float64]
    inside: NDArray[np.bool_]
    center_depth: NDArray[np.float64]


def raster_rays(intrinsics: Intrinsics, width: int, height: int) -> tuple[NDArray, NDArray]:
    """Normalised ray coordinates of the raster's pixel centres: x (width,), y (height,) float64."""
    u = (np.arange(width) + 0.5) * (intrinsics.width / width) - 0.5
    v = (np.arange(height) + 0.5) * (intrinsics.height / height) - 0.5
    return (u - intrinsics.cx) / intrinsics.fx, (v - intrinsics.cy) / intrinsics.fy


_PAIRS = ((0, 0), (0, 1), (0, 2), (1, 1), (1, 2), (2, 2))


def _camera_frame(ellipsoids: Sequence[Ellipsoid], poses: Sequence[Pose]) -> tuple[NDArray, NDArray, NDArray]:
    """Camera-frame centres m (3, C, E), and the entries xx, xy, xz, yy, yz, zz (6, C, E) of the shapes
    A' = R^T A R and of their inverses N = R^T A^-1 R (one BLAS product each, not C * E small ones)."""
    centers = np.stack([e.center for e in ellipsoids])
    shapes = np.stack([e.shape_matrix for e in ellipsoids])
    covs = np.stack([(e.rotation * e.axes**2) @ e.rotation.T for e in ellipsoids])
    R = np.array([p.rotation for p in poses])
    t = np.array([p.translation for p in poses])
    C, E = len(R), len(centers)
    m = np.einsum("cai,cea->ice", R, centers[None, :, :] - t[:, None, :])
    outer = np.stack([np.einsum("ca,cb->cab", R[:, :, i], R[:, :, j]).reshape(C, 9) for i, j in _PAIRS])  # (6, C, 9)
    flat = outer.reshape(6 * C, 9)
    A = (flat @ shapes.reshape(E, 9).T).reshape(6, C, E)
    N = (flat @ covs.reshape(E, 9).T).reshape(6, C, E)
    return m, A, N


def _tangent_range(mx: NDArray, mz: NDArray, Nxx: NDArray, Nxz: NDArray, D: NDArray) -> tuple[NDArray, NDArray]:
    """Smallest and largest x/z over an ellipsoid in front of the camera (D > 0), elementwise."""
    p = mx * mz - Nxz
    root = np.sqrt(np.maximum(p * p - D * (mx * mx - Nxx), 0.0))
    return (p - root) / D, (p + root) / D


def _pixel_span(lo: NDArray, hi: NDArray, rays: NDArray) -> tuple[NDArray, NDArray]:
    """First and last raster index whose ray coordinate lies in [lo, hi] (rays ascending); last < first if none."""
    return np.searchsorted(rays, lo, side="left"), np.searchsorted(rays, hi, side="right") - 1


_LADDER = 2 ** np.arange(11)
"""Tile sizes: a box is tested as a dense tile of the next power of two up (fewer, larger groups beat tighter
tiles: measured 10-20 % faster than a 1.5x ladder)."""


def _buckets(nx: NDArray[np.int64], ny: NDArray[np.int64]) -> list[tuple[NDArray[np.int64], int, int]]:
    """Pairs grouped by tile size: (pair indices, tile width, tile height) per group."""
    if len(nx) == 0:
        return []
    bx = np.searchsorted(_LADDER, nx)
    by = np.searchsorted(_LADDER, ny)
    key = bx * len(_LADDER) + by
    order = np.argsort(key, kind="stable")
    keys, starts = np.unique(key[order], return_index=True)
    bounds = [*starts[1:], len(order)]
    return [
        (order[lo:hi], int(_LADDER[k // len(_LADDER)]), int(_LADDER[k % len(_LADDER)]))
        for k, lo, hi in zip(keys, starts, bounds, strict=True)
    ]


def _tile_hits(
    coef: NDArray[np.float32],
    box: NDArray[np.int64],
    xs: NDArray[np.float32],
    ys: NDArray[np.float32],
    bw: int,
    bh: int,
    cam: NDArray[np.int64],
    ell: NDArray[np.int64],
    front_only: bool,
) -> tuple[NDArray[np.int64], NDArray[np.int64], NDArray[np.int64], NDArray[np.float32]]:
    """Hits of P pairs tested over dense (P, bh, bw) tiles: camera, ellipsoid, raster pixel, depth per hit.

    coef: (10, P) ray polynomial coefficients; box: (4, P) first column, first row, columns, rows.
    front_only: every pair lies in front of the camera, so a real root is a hit (``b > 0`` holds).
    """
    w, h = len(xs), len(ys)
    di, dj = np.arange(bw), np.arange(bh)
    x = xs[np.minimum(box[0][:, None] + di, w - 1)][:, None, :]  # (P, 1, bw)
    y = ys[np.minimum(box[1][:, None] + dj, h - 1)][:, :, None]  # (P, bh, 1)
    c = coef[:, :, None, None]
    # separable parts first (small arrays), then 6 passes over the (P, bh, bw) tile
    a = ((c[0] * x + c[3]) * x + (c[2] * y + c[4]) * y + c[5]) + (c[1] * x) * y
    b = c[6] * x + (c[7] * y + c[8])
    disc = b * b - a * c[9]
    inbox = (di < box[2][:, None])[:, None, :] & (dj < box[3][:, None])[:, :, None]
    hit = (disc >= 0) & inbox
    if not front_only:
        hit &= b > 0
    flat = np.flatnonzero(hit)  # flat indices: one gather per array instead of three-index gathers
    depth = (b.ravel()[flat] - np.sqrt(disc.ravel()[flat])) / a.ravel()[flat]
    p, rq = np.divmod(flat, bh * bw)
    r, q = np.divmod(rq, bw)
    return cam[p], ell[p], (box[1][p] + r) * w + box[0][p] + q, depth


def rasterize(
    ellipsoids: Sequence[Ellipsoid],
    poses: Sequence[Pose],
    intrinsics: Intrinsics,
    width: int,
    height: int,
    focus: NDArray[np.bool_] | None = None,
) -> Fragments:
    """Every ray hit of every ellipsoid (E) in the ``width x height`` raster of every camera (C, ``T_world_camera``).

    focus: (E,) bool or None. If given, the other ellipsoids are only rasterised inside each camera's
    bounding box of the focus ellipsoids' pixels (nothing where no focus ellipsoid is in view): enough
    when only the pixels of the focus ellipsoids matter, and much less work.
    """
    for i, e in enumerate(ellipsoids):
        if not isinstance(e, Ellipsoid):
            raise ValueError(f"ellipsoids[{i}]: expected an Ellipsoid, got {type(e).__name__}")
    for i, p in enumerate(poses):
        if not isinstance(p, Pose):
            raise ValueError(f"poses[{i}]: expected a Pose, got {type(p).__name__}")
    if not isinstance(intrinsics, Intrinsics):
        raise ValueError(f"intrinsics: expected an Intrinsics, got {type(intrinsics).__name__}")
    for name, n in (("width", width), ("height", height)):
        if isinstance(n, bool) or int(n) != n or n < 1:
            raise ValueError(f"{name}: must be a positive integer, got {n!r}")
    C, E = len(poses), len(ellipsoids)
    empty = np.zeros(0, dtype=np.int64)
    if C == 0 or E == 0:
        none = np.zeros((C, E), dtype=bool)
        return Fragments(width, height, C, E, empty, empty, empty, np.zeros(0), none, np.zeros((C, E)))
    xs, ys = raster_rays(intrinsics, width, height)
    m, A, N = _camera_frame(ellipsoids, poses)
    Axx, Axy, Axz, Ayy, Ayz, Azz = A
    Nxx, _, Nxz, Nyy, Nyz, Nzz = N
    Am = np.stack(
        [
            Axx * m[0] + Axy * m[1] + Axz * m[2],
            Axy * m[0] + Ayy * m[1] + Ayz * m[2],
            Axz * m[0] + Ayz * m[1] + Azz * m[2],
        ]
    )
    g = (m * Am).sum(axis=0) - 1.0
    inside = g <= 0.0
    mz = m[2]
    D = mz * mz - Nzz
    front = ~inside & (mz > 0) & (1e-12 * mz * mz < D)
    cross = ~inside & ~front & ~((mz < 0) & (D > 0))  # crosses z = 0: test every pixel
    with np.errstate(divide="ignore", invalid="ignore"):
        Ds = np.where(front, D, 1.0)
        x_lo, x_hi = _tangent_range(m[0], mz, Nxx, Nxz, Ds)
        y_lo, y_hi = _tangent_range(m[1], mz, Nyy, Nyz, Ds)
    i0, i1 = _pixel_span(x_lo, x_hi, xs)
    j0, j1 = _pixel_span(y_lo, y_hi, ys)
    i0, i1 = np.where(front, i0, 0), np.where(front, i1, width - 1)
    j0, j1 = np.where(front, j0, 0), np.where(front, j1, height - 1)
    visible = front | cross
    if focus is not None:
        f = np.asarray(focus, dtype=bool)
        if f.shape != (E,):
            raise ValueError(f"focus: expected shape ({E},), got {f.shape}")
        on = visible & f[None, :] & (i1 >= i0) & (j1 >= j0)
        big = max(width, height)
        lo_i, hi_i = np.where(on, i0, big).min(axis=1, keepdims=True), np.where(on, i1, -1).max(axis=1, keepdims=True)
        lo_j, hi_j = np.where(on, j0, big).min(axis=1, keepdims=True), np.where(on, j1, -1).max(axis=1, keepdims=True)
        i0, i1 = np.where(f, i0, np.maximum(i0, lo_i)), np.where(f, i1, np.minimum(i1, hi_i))
        j0, j1 = np.where(f, j0, np.maximum(j0, lo_j)), np.where(f, j1, np.minimum(j1, hi_j))
    active = visible & (i1 >= i0) & (j1 >= j0)
    pc, pe = np.nonzero(active)
    # per active pair: the ray polynomial's coefficients (see the module docstring), float32 for speed
    coef = np.stack(
        [Axx, 2.0 * Axy, Ayy, 2.0 * Axz, 2.0 * Ayz, Azz, Am[0], Am[1], Am[2], g], axis=-1, dtype=np.float32
    )[pc, pe].T  # (10, P)
    box = np.stack([i0[pc, pe], j0[pc, pe], i1[pc, pe] - i0[pc, pe] + 1, j1[pc, pe] - j0[pc, pe] + 1])  # (4, P)
    x32, y32, is_front = xs.astype(np.float32), ys.astype(np.float32), front[pc, pe]
    parts = [
        _tile_hits(coef[:, sel], box[:, sel], x32, y32, bw, bh, pc[sel], pe[sel], bool(np.all(is_front[sel])))
        for sel, bw, bh in _buckets(box[2], box[3])
    ]
    cam = np.concatenate([q[0] for q in parts]) if parts else empty
    ell = np.concatenate([q[1] for q in parts]) if parts else empty
    pix = np.concatenate([q[2] for q in parts]) if parts else empty
    depth = np.concatenate([q[3] for q in parts]).astype(np.float64) if parts else np.zeros(0)
    ic, ie = np.nonzero(inside)  # camera inside: every pixel at depth 0
    if len(ic):
        n_pix = width * height
        cam = np.concatenate([cam, np.repeat(ic, n_pix)])
        ell = np.concatenate([ell, np.repeat(ie, n_pix)])
        pix = np.concatenate([pix, np.tile(np.arange(n_pix), len(ic))])
        depth = np.concatenate([depth, np.zeros(len(ic) * n_pix)])
    return Fragments(width, height, C, E, cam, ell, pix, depth, inside, m[2])
