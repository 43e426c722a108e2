"""Spheres in a depth frame: segment the points near where a sphere should be, fit its centre by least squares.

:func:`fit_sphere` is scipy's ``least_squares`` on the geometric residual ``|p - c| - r`` (radius known or free)
with a soft-L1 loss, so flying pixels at the silhouette and a post's points weigh little; a second pass drops the
points farther than ``TRIM`` from the first fit's surface.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray
from scipy.optimize import least_squares

MIN_POINTS = 60
"""A sphere with fewer points than this in its window is 'not seen'."""
TRIM = 0.003
"""Second pass: points farther than this from the first fit's surface are dropped, metres."""
LOSS_SCALE = 0.001
"""Soft-L1 scale of the fit: residuals beyond about this count linearly, metres."""


@dataclass(frozen=True)
class SphereFit:
    """centre: (3,) float64 (the points' frame). radius: fitted (or the known one). rms: of the residuals of the
    points kept, metres. points: how many were kept."""

    centre: NDArray[np.float64]
    radius: float
    rms: float
    points: int


def fit_sphere(
    points: NDArray[np.float64], radius: float | None = None, start: NDArray[np.float64] | None = None
) -> SphereFit:
    """Fit a sphere to points (N, 3) of its surface (a cap is enough). radius: known (only the centre is fitted)
    or None (fitted too). start: (3,) a centre guess (default: the centroid pushed back from the origin, the
    camera, by the radius). ValueError if fewer than ``MIN_POINTS`` points."""
    p = np.asarray(points, dtype=np.float64)
    if p.ndim != 2 or p.shape[1] != 3 or len(p) < MIN_POINTS:
        raise ValueError(f"sphere fit: need at least {MIN_POINTS} points (N, 3), got {p.shape}")
    if start is None:
        centroid = p.mean(axis=0)
        spread = float(np.sqrt(((p - centroid) ** 2).sum(axis=1).mean()))
        r0 = radius if radius is not None else spread * 1.3
        c0 = centroid + r0 * 0.6 * centroid / max(float(np.linalg.norm(centroid)), 1e-9)
    else:
        c0 = np.asarray(start, dtype=np.float64)
        r0 = radius if radius is not None else float(np.linalg.norm(p - c0, axis=1).mean())
    x = c0 if radius is not None else np.append(c0, r0)
    for keep in (np.ones(len(p), dtype=bool), None):
        if keep is None:
            r = radius if radius is not None else float(x[3])
            keep = np.abs(np.linalg.norm(p - x[:3], axis=1) - r) < TRIM
            if int(keep.sum()) < MIN_POINTS:
                raise ValueError(f"sphere fit: only {int(keep.sum())} points within {TRIM * 1000:.0f} mm of the fit")
        q = p[keep]

        def residual(v: NDArray[np.float64], q: NDArray[np.float64] = q) -> NDArray[np.float64]:
            r = radius if radius is not None else v[3]
            return np.linalg.norm(q - v[:3], axis=1) - r

        def jacobian(v: NDArray[np.float64], q: NDArray[np.float64] = q) -> NDArray[np.float64]:
            """(M, 3) or (M, 4): d residual / d centre = -(q - c) / |q - c|, d residual / d radius = -1."""
            d = q - v[:3]
            unit = d / np.maximum(np.linalg.norm(d, axis=1), 1e-12)[:, None]
            return -unit if radius is not None else np.hstack([-unit, -np.ones((len(q), 1))])

        x = least_squares(residual, x, jac=jacobian, loss="soft_l1", f_scale=LOSS_SCALE, method="trf").x  # pyright: ignore[reportArgumentType]  (its stubs type jac as a str)
    q = p[keep]
    r = float(radius if radius is not None else x[3])
    res = np.linalg.norm(q - x[:3], axis=1) - r
    return SphereFit(np.array(x[:3]), r, float(np.sqrt(np.mean(res**2))), len(q))


def find_spheres(
    points_camera: NDArray[np.float64], predicted_camera: NDArray[np.float64], radius: float, window: float = 0.03
) -> list[SphereFit | None]:
    """Fit each target sphere in one frame. points_camera: (N, 3) the frame's points. predicted_camera: (K, 3) where
    the centres should be (from the nominal calibration), camera frame. Points within ``radius + window`` of a
    prediction (and nearer to it than to any other) are its cap; None for a sphere with too few points or a fit
    that lands more than ``window`` from its prediction. A second fit takes the points within ``radius + TRIM``
    of the first fit's centre (the post and the plate fall away)."""
    p = np.asarray(points_camera, dtype=np.float64)
    pred = np.asarray(predicted_camera, dtype=np.float64)
    out: list[SphereFit | None] = []
    if len(p) == 0:
        return [None] * len(pred)
    reach = radius + window
    # the points inside the box of some prediction's window: every other point is farther than ``reach`` from
    # every prediction (in no cap), and a box test costs a fraction of the distances to every prediction
    close = np.flatnonzero(_in_any_box(p, pred, reach))
    distances = np.linalg.norm(p[close, None, :] - pred[None, :, :], axis=2)  # (M, K)
    nearest = distances.argmin(axis=1)
    for k in range(len(pred)):
        mask = (nearest == k) & (distances[:, k] < reach)
        if int(mask.sum()) < MIN_POINTS:
            out.append(None)
            continue
        try:
            fit = fit_sphere(p[close[mask]], radius, start=pred[k])
            fit = fit_sphere(p[_within(p, close, pred[k], reach, fit.centre, radius + TRIM)], radius, start=fit.centre)
        except ValueError:
            out.append(None)
            continue
        out.append(fit if float(np.linalg.norm(fit.centre - pred[k])) < window else None)
    return out


def _in_any_box(p: NDArray[np.float64], centres: NDArray[np.float64], half: float) -> NDArray[np.bool_]:
    """(N,) whether each point of ``p`` (N, 3) lies in the axis-aligned cube of half-side ``half`` about one of
    ``centres`` (K, 3): the box of them all first, one coordinate at a time, then each cube among those in it."""
    lo, hi = centres.min(axis=0) - half, centres.max(axis=0) + half
    candidates = np.flatnonzero((p[:, 2] >= lo[2]) & (p[:, 2] <= hi[2]))
    for axis in (0, 1):
        column = p[candidates, axis]
        candidates = candidates[(column >= lo[axis]) & (column <= hi[axis])]
    near = p[candidates]
    inside = np.zeros(len(candidates), dtype=bool)
    for c in centres:
        inside |= (np.abs(near - c) <= half).all(axis=1)
    out = np.zeros(len(p), dtype=bool)
    out[candidates[inside]] = True
    return out


def _within(
    p: NDArray[np.float64],
    close: NDArray[np.intp],
    window_centre: NDArray[np.float64],
    reach: float,
    centre: NDArray[np.float64],
    limit: float,
) -> NDArray[np.intp]:
    """Indices, ascending, of the points of ``p`` (N, 3) nearer than ``limit`` to ``centre``: searched among
    ``close`` (the points in the cubes of half-side ``reach`` about the predictions) when the ball lies in the cube
    about ``window_centre``, else among all."""
    inside = float(np.abs(centre - window_centre).max()) + limit <= reach
    pool = close if inside else np.arange(len(p))
    pool = pool[(np.abs(p[pool] - centre) < limit).all(axis=1)]
    return pool[np.linalg.norm(p[pool] - centre, axis=1) < limit]
