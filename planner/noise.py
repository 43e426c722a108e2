"""What the sensor's depth noise means for the planner's thresholds (pure numpy).

A perfect sensor needs none of this (``NoiseConfig`` at its defaults leaves every threshold as the paper's). A
noisy one scatters the plate's points above its top: a fixed 2 mm band keeps a quarter of a 2 mm-noise frame as
"object", and B grows to the plate's extent. The band here follows the noise at each point's range, projected on
the vertical; ICP's rmse gate follows the noise at the frame's median range.
"""

from __future__ import annotations

import dataclasses
import math

import numpy as np
from numpy.typing import NDArray

from planner.config import NoiseConfig, PreprocessConfig, RegistrationConfig
from planner.types import DepthFrame, Pose


def depth_std(depth: NDArray[np.floating], noise: NoiseConfig) -> NDArray[np.float64]:
    """(N,) std of the depth error at planar depths ``depth`` (N,), metres."""
    z = np.asarray(depth, dtype=np.float64)
    return np.sqrt(noise.depth_std**2 + (noise.depth_z2 * z * z) ** 2)


MAX_PLATE_TILT = math.radians(3.0)
"""A fitted plate plane steeper than this (or offset by more than the fit window) is not believed: z = 0 is used."""
MIN_PLATE_POINTS = 200
"""Fewer plate candidates than this: no fit, z = 0."""


NORMAL_STENCIL_PX = 3
""":func:`vertical_cosines` takes a pixel's tangents from the pixels this far to each side (a 2 x 3 px baseline
averages the depth noise: a D435 at 0.55 m tilts a 5 mm baseline's normal by about 10 degrees)."""


def vertical_cosines(
    frame: DepthFrame, stencil: int = NORMAL_STENCIL_PX, at: NDArray[np.intp] | None = None
) -> NDArray[np.float64]:
    """(N,) per point of ``frame.points_world``: |cos| of the angle between the surface normal there and the world
    vertical, the normal from the cross product of the differences of the points ``stencil`` pixels to either side
    along the row and the column (0 where one of the four has no return or lies off the image: an edge, a hole).
    at (K,): only those points (indices into ``frame.points_world``), (K,) values, the same as the whole frame's.

    The four neighbours of each point are gathered through an image of point indices, and the cross product is
    taken in the camera frame with only its vertical component rotated to the world (a rotation keeps cross
    products): the same values to 1e-13 as rotating the whole image first and crossing every pixel's tangents, at
    a fraction of the cost (the plate fit asks only the points near the plate; the D435 model asks twice a frame)."""
    d = frame.depth
    h, w = d.shape
    valid = d > 0
    rows, cols = np.nonzero(valid)  # the order of frame.points_world
    idx = np.arange(len(rows)) if at is None else np.asarray(at, dtype=np.intp)
    r, c = rows[idx], cols[idx]
    s = int(stencil)
    index = np.full((h + 2 * s, w + 2 * s), -1, dtype=np.int64)  # -1: no return, or off the image
    index[s : s + h, s : s + w][valid] = np.arange(len(rows))
    right, left = index[r + s, c + 2 * s], index[r + s, c]
    below, above = index[r + 2 * s, c + s], index[r, c + s]
    ok = (right >= 0) & (left >= 0) & (below >= 0) & (above >= 0)
    out = np.zeros(len(idx))
    if not np.any(ok):
        return out
    p = frame.points_camera
    du = p[right[ok]] - p[left[ok]]
    dv = p[below[ok]] - p[above[ok]]
    ux, uy, uz = du[:, 0], du[:, 1], du[:, 2]
    vx, vy, vz = dv[:, 0], dv[:, 1], dv[:, 2]
    nx = uy * vz - uz * vy
    ny = uz * vx - ux * vz
    nz = ux * vy - uy * vx
    up = frame.T_world_camera.rotation[2]  # the world's vertical component of a camera-frame vector
    vertical = up[0] * nx + up[1] * ny + up[2] * nz
    norm = np.sqrt(nx * nx + ny * ny + nz * nz)
    out[ok] = np.where(norm > 0, np.abs(vertical) / np.where(norm > 0, norm, 1.0), 0.0)
    return out


def plate_window(points_world: NDArray[np.float64], window: float, workspace_radius: float) -> NDArray[np.bool_]:
    """(N,) the points :func:`fit_plate` fits to: within ``window`` of z = 0 and ``workspace_radius`` of the axis."""
    p = points_world
    return (np.abs(p[:, 2]) <= window) & (p[:, 0] ** 2 + p[:, 1] ** 2 <= workspace_radius**2)


def fit_plate(
    points_world: NDArray[np.float64],
    window: float,
    workspace_radius: float,
    candidates: NDArray[np.bool_] | None = None,
    near: NDArray[np.bool_] | None = None,
) -> NDArray[np.float64]:
    """(3,) (a, b, c) of the plate plane ``z = a x + b y + c`` seen in one frame, from the points within ``window``
    of z = 0 and ``workspace_radius`` of the axis (``near`` (N,) bool: that window, when the caller has it already,
    :func:`plate_window`).

    Robust to the two things besides the plate top in that window: the object's foot and the plate's rim (its
    vertical side, z from 0 down to -thickness, which a low view sees head-on while the grazing limit drops most
    of the top). Both spread over the window's heights, the top is one thin layer: the start is the flat plane at
    the densest 1 mm height bin, the first inliers the points within 2 mm of it; then four times a least-squares
    fit to the inliers and new inliers within 3 robust stds (1.4826 MAD of the inliers' residuals, at least
    0.5 mm). (A least-squares start on every point of the window, as before, put the plane 4 mm below the top
    or tilted it by 2 degrees on such views.) ``candidates`` (N,) bool, when given, also limits the fit to those
    points (:func:`plate_heights`: the points on a near-horizontal surface, so a view that sees the rim but not the
    top, beyond a sensor's grazing limit, is left with too few). (0, 0, 0) when there are too few points or the
    plane is implausible."""
    p = points_world
    near = plate_window(p, window, workspace_radius) if near is None else near.copy()
    if candidates is not None:
        near &= candidates
    q = p[near]
    zero = np.zeros(3)
    if len(q) < MIN_PLATE_POINTS:
        return zero
    A = np.column_stack([q[:, 0], q[:, 1], np.ones(len(q))])
    counts, edges = np.histogram(q[:, 2], bins=max(1, round(2 * window / 0.001)), range=(-window, window))
    top = int(np.argmax(counts))
    coef = np.array([0.0, 0.0, 0.5 * (edges[top] + edges[top + 1])])
    keep = np.abs(q[:, 2] - coef[2]) <= 0.002
    for _ in range(4):
        if np.count_nonzero(keep) < MIN_PLATE_POINTS:
            return zero
        coef, *_ = np.linalg.lstsq(A[keep], q[keep, 2], rcond=None)
        residual = q[:, 2] - A @ coef
        scale = max(1.4826 * float(np.median(np.abs(residual[keep]))), 0.0005)
        keep = np.abs(residual) <= 3.0 * scale
    if math.hypot(coef[0], coef[1]) > math.tan(MAX_PLATE_TILT) or abs(coef[2]) > window:
        return zero
    return np.asarray(coef, dtype=np.float64)


def plate_plane(frame: DepthFrame, preprocess: PreprocessConfig, noise: NoiseConfig) -> NDArray[np.float64]:
    """(3,) (a, b, c) of the plate's surface ``z = a x + b y + c`` in ``frame``: the frame's fitted plane with
    ``noise.fit_plate`` (:func:`fit_plate`; with ``noise.plate_fit_max_tilt_deg`` < 90 only points whose surface
    normal, :func:`vertical_cosines`, is within that angle of the vertical), else z = 0 (zeros)."""
    if noise.exact or not noise.fit_plate:
        return np.zeros(3)
    points = frame.points_world
    near = plate_window(points, noise.plate_fit_window, preprocess.workspace_radius)
    horizontal = None
    if noise.plate_fit_max_tilt_deg < 90:  # asked only where the fit looks: the points in its window
        horizontal = np.zeros(len(points), dtype=bool)
        at = np.flatnonzero(near)
        horizontal[at] = vertical_cosines(frame, at=at) >= math.cos(math.radians(noise.plate_fit_max_tilt_deg))
    return fit_plate(points, noise.plate_fit_window, preprocess.workspace_radius, horizontal, near)


def plane_moved(plane: NDArray[np.float64], T_new_old: Pose) -> NDArray[np.float64]:
    """(3,) the plane ``z = a x + b y + c`` (``plane`` (3,), in frame "old") in frame "new" (``x_new = T_new_old
    x_old``): a registration's correction moves the frame's points, and the plate fitted to them with them."""
    a, b, c = (float(v) for v in plane)
    normal = T_new_old.rotation @ np.array([-a, -b, 1.0])
    offset = c + float(normal @ T_new_old.translation)
    return np.array([-normal[0] / normal[2], -normal[1] / normal[2], offset / normal[2]])


def plate_heights(
    frame: DepthFrame,
    preprocess: PreprocessConfig,
    noise: NoiseConfig,
    plane: NDArray[np.float64] | None = None,
) -> NDArray[np.float64]:
    """(N,) per point of ``frame.points_world``: below this height above z = 0 a point is plate.

    The plate's surface (``plane``, (3,) as :func:`plate_plane` gives it; None: :func:`plate_plane` of this frame)
    plus ``max(plate_clearance, plate_sigmas * sigma_z)``, where sigma_z is the depth std at the point's depth
    times the vertical component of its ray (a ray along the vertical moves the point up and down by its whole
    error, a grazing one hardly at all)."""
    v, u = frame.pixels
    if noise.exact:
        return np.full(len(v), preprocess.plate_clearance)
    depth = frame.depth[v, u].astype(np.float64)
    points = frame.points_world
    vertical = np.abs(points[:, 2] - frame.T_world_camera.translation[2]) / np.maximum(depth, 1e-9)
    band = np.maximum(preprocess.plate_clearance, noise.plate_sigmas * depth_std(depth, noise) * vertical)
    if not noise.fit_plate:
        return band
    a, b, c = plate_plane(frame, preprocess, noise) if plane is None else plane
    return band + a * points[:, 0] + b * points[:, 1] + c


def without_flying_pixels(frame: DepthFrame, jump: float) -> DepthFrame:
    """``frame`` with the pixels at depth discontinuities set to "no return": a pixel whose 4-neighbour (with a
    return) differs by more than ``jump`` times its depth, on both sides of the edge. ``jump`` 0: unchanged."""
    if jump <= 0:
        return frame
    d = frame.depth
    edge = np.zeros(d.shape, dtype=bool)
    for a, b, sa, sb in (
        (d[:-1], d[1:], (slice(None, -1),), (slice(1, None),)),
        (d[:, :-1], d[:, 1:], (slice(None), slice(None, -1)), (slice(None), slice(1, None))),
    ):
        jumps = (a > 0) & (b > 0) & (np.abs(a - b) > jump * np.minimum(a, b))
        edge[sa] |= jumps
        edge[sb] |= jumps
    if not np.any(edge):
        return frame
    return DepthFrame(np.where(edge, np.float32(0.0), d).astype(np.float32), frame.T_world_camera, frame.intrinsics)


def dropouts_filled(frame: DepthFrame, radius_px: int) -> DepthFrame:
    """The frame as the voxel map should carve it when a missing depth may be a dropout: every pixel without a
    return within ``radius_px`` (a square window) of one with a return takes the nearest (smallest) depth of that
    window, so its ray is free only up to there and unknown beyond (no point is added for it). ``radius_px`` 0:
    unchanged."""
    if radius_px <= 0:
        return frame
    from scipy.ndimage import minimum_filter

    d = frame.depth
    hole = d == 0
    if not np.any(hole):
        return frame
    rows, cols = np.flatnonzero(~hole.all(axis=1)), np.flatnonzero(~hole.all(axis=0))
    if len(rows) == 0:  # no return at all: nothing to fill from
        return frame
    # Only the returns' box, widened by the radius, can be filled: the filter runs there (outside it every pixel in
    # reach is a hole, as outside the image: the same minimum as over the whole image).
    r0, r1 = max(rows[0] - radius_px, 0), min(rows[-1] + radius_px + 1, d.shape[0])
    c0, c1 = max(cols[0] - radius_px, 0), min(cols[-1] + radius_px + 1, d.shape[1])
    near = np.full(d.shape, np.inf, dtype=np.float32)
    crop = np.where(hole[r0:r1, c0:c1], np.float32(np.inf), d[r0:r1, c0:c1])
    near[r0:r1, c0:c1] = minimum_filter(crop, size=2 * radius_px + 1, mode="constant", cval=np.inf)
    filled = np.where(hole & np.isfinite(near), near, d).astype(np.float32)
    return DepthFrame(filled, frame.T_world_camera, frame.intrinsics)


def unknown_beyond_range(carve: DepthFrame, measured: DepthFrame, max_range: float) -> DepthFrame:
    """``carve`` (the frame the voxel map carves) with every pixel that has no return in ``measured`` (the sensor's
    frame) and none in ``carve`` set to ``max_range``: a sensor says nothing beyond its range, so such a ray is free
    space up to ``max_range`` (planar depth, metres) and unknown beyond (the paper's rule, "no return is free
    space", assumes a range beyond B). Pixels ``carve`` already filled (dropouts) or cleared (the plate, which has a
    return in ``measured``) are left alone. ``max_range`` 0: unchanged."""
    if max_range <= 0:
        return carve
    silent = (measured.depth == 0) & (carve.depth == 0)
    if not np.any(silent):
        return carve
    depth = np.where(silent, np.float32(max_range), carve.depth).astype(np.float32)
    return DepthFrame(depth, carve.T_world_camera, carve.intrinsics)


def registration_for(frame: DepthFrame, config: RegistrationConfig, noise: NoiseConfig) -> RegistrationConfig:
    """``config`` with its rmse gate raised to ``icp_sigmas * sqrt(2) * sigma(median depth)`` when that is larger
    (two noisy clouds: the frame's and the accumulated one's), and the correspondence distance kept above three
    times the gate. A perfect sensor gets ``config`` unchanged."""
    if noise.exact or not np.any(frame.valid):
        return config
    sigma = float(depth_std(np.array([np.median(frame.depth[frame.valid])]), noise)[0])
    gate = noise.icp_sigmas * math.sqrt(2.0) * sigma
    if gate <= config.max_rmse:
        return config
    return dataclasses.replace(config, max_rmse=gate)
