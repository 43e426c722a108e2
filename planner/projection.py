"""Ellipsoids seen by pinhole cameras: dual quadric -> conic, and the pixels inside it (paper §III-E).

Paper equations, with the projection written out correctly for a camera pose
``T_world_camera = (R, t)`` (camera -> world; the paper's ``R^-1 t`` drops a sign)::

    P  = K [R^T | -R^T t]              (3, 4), world -> pixels
    Φ* = P Q* P^T                      dual conic, Q* = Ellipsoid.dual()
    Φ  = (Φ*)^-1                       point conic, up to scale

``L`` is the number of pixels whose centre lies inside the projected outline,
pixel ``(u, v)`` centred at integer coordinates ``u = 0..W-1``, ``v = 0..H-1``.
Two ways to count it:

- ``raster`` (reference, slow): count pixel centres inside Φ, within the
  ellipse's bounding box clipped to the image.
- ``analytic`` (fast, vectorised over every camera x ellipsoid pair): the exact
  area of the ellipse intersected with the image rectangle
  ``[-0.5, W - 0.5] x [-0.5, H - 0.5]``. An affine map takes the ellipse to the unit
  disk and the rectangle to a parallelogram; the disk-polygon area is a sum of
  signed per-edge triangle/sector pieces. It differs from the raster count by the
  boundary pixels only (< 1 % for ellipses over ~200 pixels).

Where an ellipsoid sits relative to the camera's ``z = 0`` plane decides the case
(``status`` codes):

- ``FRONT`` (entirely ``z > 0``): the outline is an ellipse; the two counts above.
- ``BEHIND`` (entirely ``z < 0``): invisible, ``L = 0``. (Φ would still be an
  ellipse, the "virtual" image through the pinhole, which must not be counted.)
- ``STRADDLE`` (crosses ``z = 0``, camera outside): Φ is a hyperbola or parabola,
  not the outline. Both methods then count exactly the pixels whose ray
  ``s * K^-1 (u, v, 1), s > 0`` hits the ellipsoid (ray-quadric roots), solved row by
  row (``ray_hit_count``, ~0.3 ms a pair). Rare anyway: candidates keep B's content
  ``d_c`` in front of the camera.
- ``INSIDE`` (camera inside the ellipsoid): every pixel's ray starts inside and
  hits it, so ``L = W * H``. Alternatives (0, "cannot be evaluated", or the
  visible area of the part in front) are arguable; we pick the literal reading of
  "pixels covered by the ellipsoid", which also makes a camera sitting inside an
  occupied ellipsoid (inside the object) maximally penalised.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from typing import Literal

import numpy as np
from numpy.typing import NDArray

from planner.types import Ellipsoid, Intrinsics, Pose

FRONT, BEHIND, STRADDLE, INSIDE = 0, 1, 2, 3
"""``status`` codes of a camera x ellipsoid pair (see the module docstring)."""

_FRONT_MARGIN = 1e-9
"""FRONT needs ``z_c^2 - N_zz > margin * z_c^2``: an ellipsoid grazing z = 0 has an
unbounded, numerically useless ellipse and takes the exact STRADDLE path."""

# ----------------------------------------------------------------------------- the paper's equations


def projection_matrix(T_world_camera: Pose, intrinsics: Intrinsics) -> NDArray[np.float64]:
    """(3, 4) float64 P = K [R^T | -R^T t], mapping homogeneous world points to pixels."""
    Rt = T_world_camera.rotation.T
    return intrinsics.K @ np.hstack([Rt, (-Rt @ T_world_camera.translation)[:, None]])


def dual_conics(P: NDArray[np.float64], duals: NDArray[np.float64]) -> NDArray[np.float64]:
    """Φ* = P Q* P^T for every pair: P (C, 3, 4), duals (E, 4, 4) -> (C, E, 3, 3)."""
    P = np.asarray(P, dtype=np.float64)
    duals = np.asarray(duals, dtype=np.float64)
    if P.ndim != 3 or P.shape[1:] != (3, 4):
        raise ValueError(f"P: expected shape (C, 3, 4), got {P.shape}")
    if duals.ndim != 3 or duals.shape[1:] != (4, 4):
        raise ValueError(f"duals: expected shape (E, 4, 4), got {duals.shape}")
    return np.einsum("cij,ejk,clk->ceil", P, duals, P, optimize=True)


def ellipse_from_dual(dual: NDArray[np.float64]) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """Centre (..., 2) and shape S (..., 2, 2) of the ellipse with dual conic ``dual`` (..., 3, 3).

    The ellipse is ``{x : (x - centre)^T S^-1 (x - centre) <= 1}``: the dual of such an
    ellipse is, up to scale, ``[[S - c c^T, -c], [-c^T, -1]]``. Meaningful only for
    ellipses (``dual[..., 2, 2] != 0`` and S positive definite).
    """
    d = np.asarray(dual, dtype=np.float64)
    Cn = d / -d[..., 2:3, 2:3]
    center = -Cn[..., :2, 2]
    S = Cn[..., :2, :2] + center[..., :, None] * center[..., None, :]
    return center, S


def conic_from_dual(dual: NDArray[np.float64]) -> NDArray[np.float64]:
    """Point conic Φ = (Φ*)^-1 (..., 3, 3), scaled so ``p^T Φ p = -1`` at an ellipse's centre.

    Then ``p^T Φ p < 0`` inside, ``= 0`` on, ``> 0`` outside the ellipse (like ``Ellipsoid.as_quadric``).
    """
    d = np.asarray(dual, dtype=np.float64)
    M = np.linalg.inv(d)
    center, _ = ellipse_from_dual(d)
    ch = np.concatenate([center, np.ones((*center.shape[:-1], 1))], axis=-1)
    s = np.einsum("...i,...ij,...j->...", ch, M, ch)
    return -M / s[..., None, None]


# ----------------------------------------------------------------------------- fast closed form, all pairs


@dataclass(frozen=True, eq=False)
class Projection:
    """Every camera x ellipsoid pair, C cameras, E ellipsoids.

    centers_camera: (C, E, 3) ellipsoid centres in each camera frame.
    status: (C, E) int8, FRONT / BEHIND / STRADDLE / INSIDE.
    ellipse_center: (C, E, 2) pixels; ellipse_shape: (C, E, 2, 2) pixels^2
    (meaningful where status == FRONT, NaN elsewhere).
    pixels: (C, E) float64, L.
    """

    centers_camera: NDArray[np.float64]
    status: NDArray[np.int8]
    ellipse_center: NDArray[np.float64]
    ellipse_shape: NDArray[np.float64]
    pixels: NDArray[np.float64]


def _stack_ellipsoids(ellipsoids: Sequence[Ellipsoid]) -> tuple[NDArray, NDArray, NDArray]:
    """centres (E, 3), shape matrices A (E, 3, 3), their inverses A^-1 (E, 3, 3)."""
    for i, e in enumerate(ellipsoids):
        if not isinstance(e, Ellipsoid):
            raise ValueError(f"ellipsoids[{i}]: expected an Ellipsoid, got {type(e).__name__}")
    if not ellipsoids:
        return np.zeros((0, 3)), np.zeros((0, 3, 3)), np.zeros((0, 3, 3))
    centers = np.stack([e.center for e in ellipsoids])
    shapes = np.stack([e.shape_matrix for e in ellipsoids])
    covs = np.stack([(e.rotation * e.axes**2) @ e.rotation.T for e in ellipsoids])
    return centers, shapes, covs


def _stack_poses(poses: Sequence[Pose]) -> tuple[NDArray, NDArray]:
    for i, p in enumerate(poses):
        if not isinstance(p, Pose):
            raise ValueError(f"poses[{i}]: expected a Pose, got {type(p).__name__}")
    if not poses:
        return np.zeros((0, 3, 3)), np.zeros((0, 3))
    return np.stack([p.rotation for p in poses]), np.stack([p.translation for p in poses])


def _quadratic_forms(vectors: NDArray, mats: NDArray, pairs: Sequence[tuple[int, int]]) -> NDArray:
    """(C, K, E): ``vectors[c, :, i]^T mats[e] vectors[c, :, j]`` for each (i, j) in ``pairs``.

    vectors (C, 3, J), mats (E, 3, 3). One BLAS product instead of C*E small ones.
    """
    outer = np.stack([np.einsum("ca,cb->cab", vectors[:, :, i], vectors[:, :, j]) for i, j in pairs], axis=1)
    C, K = outer.shape[:2]
    return (outer.reshape(C * K, 9) @ mats.reshape(-1, 9).T).reshape(C, K, len(mats))


def project(
    ellipsoids: Sequence[Ellipsoid],
    poses: Sequence[Pose],
    intrinsics: Intrinsics,
    area: Literal["analytic", "raster"] = "analytic",
) -> Projection:
    """Project every ellipsoid (E) into every camera (C, poses are ``T_world_camera``) and count L."""
    if not isinstance(intrinsics, Intrinsics):
        raise ValueError(f"intrinsics: expected an Intrinsics, got {type(intrinsics).__name__}")
    if area not in ("analytic", "raster"):
        raise ValueError(f"area: 'analytic' or 'raster', got {area!r}")
    centers, shapes, covs = _stack_ellipsoids(ellipsoids)
    R, t = _stack_poses(poses)
    C, E = len(R), len(centers)
    # camera-frame centres: R^T (c - t)
    cc = (centers @ R.transpose(1, 0, 2).reshape(3, 3 * C)).reshape(E, C, 3).transpose(1, 0, 2)
    cc = cc - np.einsum("cai,ca->ci", R, t)[:, None, :]
    # camera-frame A^-1 entries N_ij = r_i^T A^-1 r_j (r_i: camera axes in the world)
    N = _quadratic_forms(R, covs, [(0, 0), (0, 1), (1, 1), (0, 2), (1, 2), (2, 2)])
    Nxx, Nxy, Nyy, Nxz, Nyz, Nzz = (N[:, k, :] for k in range(6))
    # camera inside: (t - c)^T A (t - c) <= 1
    tA_t = _quadratic_forms(t[:, :, None], shapes, [(0, 0)])[:, 0, :]
    Ac = np.einsum("eij,ej->ei", shapes, centers)
    inside = tA_t - 2.0 * t @ Ac.T + np.einsum("ei,ei->e", centers, Ac)[None, :] <= 1.0

    z = cc[..., 2]
    D = z * z - Nzz  # > 0 iff the ellipsoid does not meet the plane z = 0
    status = np.full((C, E), STRADDLE, dtype=np.int8)
    front = (z > 0) & (_FRONT_MARGIN * z * z < D)
    status[front] = FRONT
    status[(z < 0) & (D > 0)] = BEHIND
    status[inside] = INSIDE

    # ellipse in normalised image coordinates (the closed form of ellipse_from_dual(P Q* P^T)), then pixels
    with np.errstate(divide="ignore", invalid="ignore"):
        Dn = np.where(front, D, np.nan)
        x, y = cc[..., 0], cc[..., 1]
        x0 = (x * z - Nxz) / Dn
        y0 = (y * z - Nyz) / Dn
        D2 = Dn * Dn
        Sxx = (Dn * Nxx + Nzz * x * x - 2.0 * z * x * Nxz + Nxz * Nxz) / D2
        Syy = (Dn * Nyy + Nzz * y * y - 2.0 * z * y * Nyz + Nyz * Nyz) / D2
        Sxy = (Dn * Nxy + Nzz * x * y - z * (x * Nyz + y * Nxz) + Nxz * Nyz) / D2
    fx, fy = intrinsics.fx, intrinsics.fy
    center_px = np.stack([fx * x0 + intrinsics.cx, fy * y0 + intrinsics.cy], axis=-1)
    S_px = np.stack([np.stack([fx * fx * Sxx, fx * fy * Sxy], -1), np.stack([fx * fy * Sxy, fy * fy * Syy], -1)], -2)

    W, H = intrinsics.width, intrinsics.height
    pixels = np.zeros((C, E))
    pixels[status == INSIDE] = float(W * H)
    if area == "analytic":
        pixels[front] = _ellipse_rect_area(
            center_px[..., 0][front],
            center_px[..., 1][front],
            S_px[..., 0, 0][front],
            S_px[..., 0, 1][front],
            S_px[..., 1, 1][front],
            W,
            H,
        )
    for ci, ei in zip(*np.nonzero((status == STRADDLE) | (front & (area == "raster"))), strict=True):
        pixels[ci, ei] = raster_pixels(ellipsoids[ei], poses[ci], intrinsics)
    for a in (cc, status, center_px, S_px, pixels):
        a.setflags(write=False)
    return Projection(cc, status, center_px, S_px, pixels)


# ----------------------------------------------------------------------------- analytic clipped area


def _disk_polygon_area_xy(x: NDArray[np.float64], y: NDArray[np.float64]) -> NDArray[np.float64]:
    """``disk_polygon_area`` on vertex coordinates x, y (N, K) kept apart (fewer temporaries)."""
    bx = np.concatenate([x[:, 1:], x[:, :1]], axis=1)
    by = np.concatenate([y[:, 1:], y[:, :1]], axis=1)
    ex, ey = bx - x, by - y
    a = ex * ex + ey * ey
    b = x * ex + y * ey
    cross_ab = x * by - y * bx
    disc = a - cross_ab * cross_ab  # = b^2 - a (|A|^2 - 1), computed without cancellation
    cuts = (disc > 0) & (a > 0)
    a_safe = np.where(cuts, a, 1.0)
    mid = -b / a_safe
    half = np.sqrt(np.where(cuts, disc, 0.0)) / a_safe
    t1 = np.where(cuts, np.clip(mid - half, 0.0, 1.0), 1.0)
    t2 = np.where(cuts, np.clip(mid + half, 0.0, 1.0), 1.0)
    p1x, p1y = x + t1 * ex, y + t1 * ey
    p2x, p2y = x + t2 * ex, y + t2 * ey
    sector_in = np.arctan2(x * p1y - y * p1x, x * p1x + y * p1y)  # A -> P1, outside the disk
    sector_out = np.arctan2(p2x * by - p2y * bx, p2x * bx + p2y * by)  # P2 -> B, outside the disk
    tri = p1x * p2y - p1y * p2x  # P1 -> P2, inside the disk
    return 0.5 * (sector_in + tri + sector_out).sum(axis=1)


def disk_polygon_area(vertices: NDArray[np.float64]) -> NDArray[np.float64]:
    """Signed area of (unit disk ∩ polygon) for N convex polygons, vertices (N, K, 2) -> (N,).

    Counter-clockwise polygons give positive areas. Per edge A -> B, the signed area of
    (disk ∩ triangle O A B): the edge is cut at its circle crossings into
    outside - inside - outside pieces; inside pieces add triangles ``cross(P, Q) / 2``,
    outside pieces add sectors ``angle(P, Q) / 2``.
    """
    v = np.asarray(vertices, dtype=np.float64)
    if v.ndim != 3 or v.shape[2] != 2 or v.shape[1] < 3:
        raise ValueError(f"vertices: expected shape (N, K>=3, 2), got {v.shape}")
    return _disk_polygon_area_xy(v[..., 0], v[..., 1])


def _ellipse_rect_area(
    cx: NDArray, cy: NDArray, sxx: NDArray, sxy: NDArray, syy: NDArray, width: int, height: int
) -> NDArray[np.float64]:
    """``ellipse_rect_area`` on the components (N,) of centre and S."""
    l00 = np.sqrt(np.maximum(sxx, 0.0))
    ok = l00 > 0
    l10 = np.where(ok, sxy / np.where(ok, l00, 1.0), 0.0)
    l11 = np.sqrt(np.maximum(syy - l10 * l10, 0.0))
    ok &= l11 > 0
    area = np.where(ok, np.pi * l00 * l11, 0.0)  # the whole ellipse
    # only ellipses whose bounding box leaves the image need clipping (half-extents: sqrt(S_xx), sqrt(S_yy))
    ry = np.sqrt(np.maximum(syy, 0.0))
    lo_x, hi_x, lo_y, hi_y = -0.5, width - 0.5, -0.5, height - 0.5
    clip = ok & ((cx - l00 < lo_x) | (cx + l00 > hi_x) | (cy - ry < lo_y) | (cy + ry > hi_y))
    if np.any(clip):
        i = np.nonzero(clip)[0]
        dx = np.array([lo_x, hi_x, hi_x, lo_x])[None, :] - cx[i, None]  # (M, 4) rectangle corners
        dy = np.array([lo_y, lo_y, hi_y, hi_y])[None, :] - cy[i, None]
        y0 = dx / l00[i, None]
        y1 = (dy - l10[i, None] * y0) / l11[i, None]
        unit = np.abs(_disk_polygon_area_xy(y0, y1))
        area[i] = np.minimum(unit, np.pi) * l00[i] * l11[i]
    return area


def ellipse_rect_area(
    center: NDArray[np.float64], S: NDArray[np.float64], width: int, height: int
) -> NDArray[np.float64]:
    """Area of ellipse ∩ [-0.5, W - 0.5] x [-0.5, H - 0.5]: center (N, 2), S (N, 2, 2) -> (N,).

    The ellipse is ``{x : (x - center)^T S^-1 (x - center) <= 1}``. With ``S = L L^T``
    (Cholesky), ``y = L^-1 (x - center)`` maps it to the unit disk and the area scales by ``det L``.
    """
    c = np.asarray(center, dtype=np.float64)
    S = np.asarray(S, dtype=np.float64)
    if c.ndim != 2 or c.shape[1] != 2:
        raise ValueError(f"center: expected shape (N, 2), got {c.shape}")
    if S.shape != (len(c), 2, 2):
        raise ValueError(f"S: expected shape ({len(c)}, 2, 2), got {S.shape}")
    return _ellipse_rect_area(c[:, 0], c[:, 1], S[:, 0, 0], S[:, 0, 1], S[:, 1, 1], width, height)


# ----------------------------------------------------------------------------- raster references


def _camera_frame(ellipsoid: Ellipsoid, T_world_camera: Pose) -> tuple[NDArray, NDArray, float]:
    """Centre c (3,) and shape A (3, 3) in the camera frame, and g = c^T A c - 1 (<= 0: camera inside)."""
    R, t = T_world_camera.rotation, T_world_camera.translation
    c = R.T @ (ellipsoid.center - t)
    A = R.T @ ellipsoid.shape_matrix @ R
    return c, A, float(c @ A @ c - 1.0)


def ray_hits(ellipsoid: Ellipsoid, T_world_camera: Pose, intrinsics: Intrinsics) -> NDArray[np.bool_]:
    """(H, W) bool: pixel rays ``s K^-1 (u, v, 1)``, ``s > 0``, that hit the ellipsoid (exact, any case).

    With c the centre and A the shape in the camera frame, ``(s d - c)^T A (s d - c) = 1`` reads
    ``a s^2 - 2 b s + g = 0``; the camera is outside when ``g > 0``, and then the (same-sign) roots
    are real and positive iff ``b^2 >= a g`` and ``b > 0``. Camera inside: every ray hits.
    """
    c, A, g = _camera_frame(ellipsoid, T_world_camera)
    k = intrinsics
    if g <= 0:
        return np.ones((k.height, k.width), dtype=bool)
    x = ((np.arange(k.width) - k.cx) / k.fx)[None, :]
    y = ((np.arange(k.height) - k.cy) / k.fy)[:, None]
    a = A[0, 0] * x * x + 2 * A[0, 1] * x * y + A[1, 1] * y * y + 2 * A[0, 2] * x + 2 * A[1, 2] * y + A[2, 2]
    Ac = A @ c
    b = Ac[0] * x + Ac[1] * y + Ac[2]
    return (b > 0) & (b * b >= a * g)


def ray_hit_count(ellipsoid: Ellipsoid, T_world_camera: Pose, intrinsics: Intrinsics) -> int:
    """``ray_hits(...).sum()`` in O(H) instead of O(W H): the same test, solved row by row.

    On image row v, with x = (u - cx) / fx, the hit test ``b^2 - a g >= 0 and b > 0`` is a quadratic
    ``q(x) >= 0`` and a linear ``b(x) > 0``. Their roots cut the row into pieces of constant sign;
    each piece is classified at its midpoint and its pixel centres (integers u in [u0, u1)) counted.
    """
    c, A, g = _camera_frame(ellipsoid, T_world_camera)
    k = intrinsics
    if g <= 0:
        return k.width * k.height
    y = (np.arange(k.height) - k.cy) / k.fy  # (H,)
    kc = A @ c
    b1 = kc[1] * y + kc[2]  # b(x) = kc0 x + b1
    a1 = A[0, 1] * y + A[0, 2]  # a(x) = A00 x^2 + 2 a1 x + a0
    a0 = A[1, 1] * y * y + 2 * A[1, 2] * y + A[2, 2]
    alpha = kc[0] ** 2 - g * A[0, 0]  # q(x) = alpha x^2 + 2 beta x + gamma
    beta = kc[0] * b1 - g * a1
    gamma = b1 * b1 - g * a0
    x_lo, x_hi = (-0.5 - k.cx) / k.fx, (k.width - 0.5 - k.cx) / k.fx
    with np.errstate(divide="ignore", invalid="ignore"):
        if alpha != 0.0:
            sq = np.sqrt(beta * beta - alpha * gamma)  # NaN without real roots
            r1, r2 = (-beta - sq) / alpha, (-beta + sq) / alpha
        else:
            r1 = r2 = -gamma / (2.0 * beta)
        xb = -b1 / kc[0] if kc[0] != 0.0 else np.full_like(y, np.nan)
    cuts = np.stack([np.full_like(y, x_lo), r1, r2, xb, np.full_like(y, x_hi)], axis=1)  # (H, 5)
    cuts = np.sort(np.clip(np.nan_to_num(cuts, nan=x_lo, posinf=x_hi, neginf=x_lo), x_lo, x_hi), axis=1)
    mid = 0.5 * (cuts[:, 1:] + cuts[:, :-1])  # (H, 4)
    q = alpha * mid * mid + 2 * beta[:, None] * mid + gamma[:, None]
    hit = (q >= 0) & (kc[0] * mid + b1[:, None] > 0)
    u = np.ceil(k.fx * cuts + k.cx)
    return int(((u[:, 1:] - u[:, :-1]) * hit).sum())


def raster_pixels(ellipsoid: Ellipsoid, T_world_camera: Pose, intrinsics: Intrinsics) -> int:
    """L by counting pixel centres (reference). FRONT: inside the paper's conic Φ from Φ* = P Q* P^T,
    searched over the ellipse's bounding box; STRADDLE: ``ray_hit_count``; BEHIND: 0; INSIDE: W * H."""
    if not isinstance(ellipsoid, Ellipsoid):
        raise ValueError(f"ellipsoid: expected an Ellipsoid, got {type(ellipsoid).__name__}")
    k = intrinsics
    R, t = T_world_camera.rotation, T_world_camera.translation
    c = R.T @ (ellipsoid.center - t)
    half_depth = float(np.sqrt(R[:, 2] @ np.linalg.inv(ellipsoid.shape_matrix) @ R[:, 2]))
    if ellipsoid.contains(t[None, :], tol=0.0)[0]:
        return k.width * k.height
    if c[2] + half_depth < 0:
        return 0
    if not (c[2] > 0 and c[2] ** 2 - half_depth**2 > _FRONT_MARGIN * c[2] ** 2):
        return ray_hit_count(ellipsoid, T_world_camera, intrinsics)
    dual = dual_conics(projection_matrix(T_world_camera, k)[None], ellipsoid.dual()[None])[0, 0]
    center, S = ellipse_from_dual(dual)
    conic = conic_from_dual(dual)
    r = np.sqrt(np.maximum(np.diag(S), 0.0))
    u_lo, u_hi = max(0, int(np.ceil(center[0] - r[0]))), min(k.width - 1, int(np.floor(center[0] + r[0])))
    v_lo, v_hi = max(0, int(np.ceil(center[1] - r[1]))), min(k.height - 1, int(np.floor(center[1] + r[1])))
    if u_lo > u_hi or v_lo > v_hi:
        return 0
    u = np.arange(u_lo, u_hi + 1, dtype=np.float64)[None, :]
    v = np.arange(v_lo, v_hi + 1, dtype=np.float64)[:, None]
    q = conic[0, 0] * u * u + 2 * conic[0, 1] * u * v + conic[1, 1] * v * v
    q = q + 2 * conic[0, 2] * u + 2 * conic[1, 2] * v + conic[2, 2]
    return int(np.count_nonzero(q <= 0))
