"""Where the plate lies in one frame as its registered pose puts it: :func:`frame_plate_plane`.

The plate's top is z = 0 in the table frame, and so it is in a frame at the pose the cell reports. But the surface
fuses each frame at its *registered* pose, and ICP may turn a frame about a direction the object hardly constrains
(a screwdriver lying on the plate: its long axis, by 5-7 degrees on a simulated scan with an ideal sensor). The
object's points still fit, but the plate seen through that pose is tilted: 0.2 m from the axis it rises 17 mm
above z = 0. Taken for the object, those points grew the object's box over the whole plate and the plate was fused
as surface, for good (F@5mm 0.98 -> 0.38). The planner moves its plate plane with the correction
(``planner.noise.plane_moved``); the integrator sees only the registered frame, so it finds the plate in it.
"""

from __future__ import annotations

import math

import numpy as np
from numpy.typing import NDArray

from planner.types import BoundingBox
from workbench.surface.config import SurfaceConfig

PLATE_FIT_WINDOW = 0.03
"""Metres: points within this of z = 0 (and within the workspace cylinder) are the fit's candidates: a plate
tilted by 8.5 degrees is still inside up to its 0.2 m rim."""
PLATE_FIT_MAX_SLOPE = math.tan(math.radians(15.0))
"""A fitted plane steeper than this is no plate (e.g. the plate's vertical rim, or the object's side)."""
PLATE_FIT_MAX_OFFSET = 0.01
"""Metres: a fitted plane whose height on the turntable axis is farther than this from 0 is no plate (e.g. a low
flat face of the object): a registration turns and shifts a frame by a few millimetres there."""
PLATE_FIT_MIN_POINTS = 300
"""Fewer inliers than this: no fit (the plate at z = 0)."""
PLATE_FIT_HYPOTHESES = 64
"""Random planes through three candidates tried (seeded: the same frame gives the same plane)."""
PLATE_FIT_SAMPLE = 4_000
"""At most this many candidates score the hypotheses (evenly strided); the winner is refined on all of them."""


def frame_plate_plane(
    points_world: NDArray[np.float64], config: SurfaceConfig, box: BoundingBox | None = None
) -> NDArray[np.float64]:
    """(3,) (a, b, c) of the plate's top ``z = a x + b y + c`` in a frame's points (N, 3) (world frame, at its
    registered pose); zeros (z = 0) when the plate lies there within ``plate_clearance / 2`` wherever it was seen
    (a frame whose pose is right: the same surface as without the fit), when z = 0 explains at least as many
    candidates, or when no plausible plate is found.

    The candidates: points within :data:`PLATE_FIT_WINDOW` of z = 0 inside the workspace cylinder and outside the
    object's footprint (``box`` grown by ``box_margin``, in x and y; None: no object known, every point): the
    object's own low faces are no plate (from a low view the plate may be a strip, the object's base a wider
    patch). A plane of three candidates (RANSAC, inliers within ``plate_clearance``), z = 0 among the hypotheses,
    refined by least squares on its inliers; rejected when steeper than :data:`PLATE_FIT_MAX_SLOPE` or farther than
    :data:`PLATE_FIT_MAX_OFFSET` from 0 on the turntable axis.
    """
    zero = np.zeros(3)
    tol = config.plate_clearance
    if tol <= 0 or len(points_world) == 0:
        return zero
    cand = points_world[np.abs(points_world[:, 2]) <= PLATE_FIT_WINDOW]
    keep = cand[:, 0] ** 2 + cand[:, 1] ** 2 <= config.workspace_radius**2
    if box is not None:
        m = config.box_margin
        keep &= ~np.all((cand[:, :2] >= box.lower[:2] - m) & (cand[:, :2] <= box.upper[:2] + m), axis=1)
    cand = cand[keep]
    if len(cand) < PLATE_FIT_MIN_POINTS:
        return zero
    sample = cand[:: max(1, len(cand) // PLATE_FIT_SAMPLE)]
    plane = _best_hypothesis(sample, tol)
    if plane is None or not plane.any():  # z = 0 explains the sample best: the pose is right (the common case)
        return zero
    for _ in range(2):  # least squares on the inliers, twice (the first fit's inliers may include a few more)
        p = cand[np.abs(cand[:, 2] - _height(plane, cand)) <= tol]
        if len(p) < PLATE_FIT_MIN_POINTS:
            return zero
        plane = _least_squares_plane(p)
    inliers = cand[np.abs(cand[:, 2] - _height(plane, cand)) <= tol]
    if (
        len(inliers) < PLATE_FIT_MIN_POINTS
        or math.hypot(plane[0], plane[1]) > PLATE_FIT_MAX_SLOPE
        or abs(plane[2]) > PLATE_FIT_MAX_OFFSET
        or len(inliers) <= np.count_nonzero(np.abs(cand[:, 2]) <= tol)
        or float(np.max(_height(plane, inliers))) < 0.5 * tol
    ):
        return zero
    return plane


def _least_squares_plane(p: NDArray[np.float64]) -> NDArray[np.float64]:
    """(3,) (a, b, c) of ``z = a x + b y + c`` fitting ``p`` (K, 3) by least squares (normal equations about the
    centroid: a 2 x 2 solve, no (K, 3) design matrix)."""
    centroid = p.mean(axis=0)
    d = p - centroid
    xx, xy, yy = float(d[:, 0] @ d[:, 0]), float(d[:, 0] @ d[:, 1]), float(d[:, 1] @ d[:, 1])
    xz, yz = float(d[:, 0] @ d[:, 2]), float(d[:, 1] @ d[:, 2])
    det = xx * yy - xy * xy
    if not det > 0:
        return np.zeros(3)  # collinear points: no plane (the caller's checks then keep z = 0)
    a, b = (yy * xz - xy * yz) / det, (xx * yz - xy * xz) / det
    return np.array([a, b, centroid[2] - a * centroid[0] - b * centroid[1]])


def plate_height(plane: NDArray[np.float64], points_world: NDArray[np.float64]) -> NDArray[np.float64]:
    """(N,) the height of the plate ``plane`` (3,) under each of ``points_world`` (N, 3)."""
    return _height(plane, points_world)


def _height(plane: NDArray[np.float64], p: NDArray[np.float64]) -> NDArray[np.float64]:
    return plane[0] * p[:, 0] + plane[1] * p[:, 1] + plane[2]


def _best_hypothesis(sample: NDArray[np.float64], tol: float) -> NDArray[np.float64] | None:
    """(3,) the plane through three of ``sample`` (K, 3) (or z = 0) with the most points within ``tol``, among the
    plausible ones (slope and offset bounds); None when fewer than three points."""
    if len(sample) < 3:
        return None
    rng = np.random.default_rng(0)
    triples = sample[rng.integers(0, len(sample), size=(PLATE_FIT_HYPOTHESES, 3))]  # (H, 3, 3)
    normal = np.cross(triples[:, 1] - triples[:, 0], triples[:, 2] - triples[:, 0])  # (H, 3)
    nz = normal[:, 2]
    ok = np.abs(nz) > 1e-12
    safe = np.where(ok, nz, 1.0)
    a, b = -normal[:, 0] / safe, -normal[:, 1] / safe
    c = triples[:, 0, 2] - a * triples[:, 0, 0] - b * triples[:, 0, 1]
    ok &= (np.hypot(a, b) <= PLATE_FIT_MAX_SLOPE) & (np.abs(c) <= PLATE_FIT_MAX_OFFSET)
    planes = np.column_stack([a, b, c])[ok]
    planes = np.vstack([np.zeros((1, 3)), planes])  # z = 0 is a hypothesis too
    residual = sample[None, :, 2] - (
        planes[:, 0:1] * sample[None, :, 0] + planes[:, 1:2] * sample[None, :, 1] + planes[:, 2:3]
    )
    counts = np.count_nonzero(np.abs(residual) <= tol, axis=1)
    return planes[int(np.argmax(counts))]
