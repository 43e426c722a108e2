"""Pure helpers for drawing a PlanResult: colours, line segments, ellipsoid instances (no viser here)."""

from __future__ import annotations

import math
from collections.abc import Sequence

import numpy as np
from numpy.typing import NDArray

from planner import BoundingBox, Ellipsoid, Pose

# A 9-stop approximation of matplotlib's viridis (low -> high score). The page draws
# its colour bar from the same stops (GET /api/scene), so scene and legend agree.
VIRIDIS: tuple[tuple[int, int, int], ...] = (
    (68, 1, 84),
    (71, 44, 122),
    (59, 81, 139),
    (44, 113, 142),
    (33, 144, 141),
    (39, 173, 129),
    (92, 200, 99),
    (170, 220, 50),
    (253, 231, 37),
)
INELIGIBLE = (175, 175, 175)

DEFAULT_LAYERS: dict[str, bool] = {
    "occupied": True,
    "frontier": True,
    "unknown": True,
    "empty": False,
    "ellipsoids": True,
    "gmm": False,
    "candidates": True,
    "nbv": True,
    "views": True,
    "bbox": True,
    "sectors": True,
    "cloud": True,
    "turntable": True,
    "mesh": False,
    "surface": False,
    "clusters": False,
    "gizmo": False,
    "reach": False,
    "path": True,
}
LAYER_NODES: dict[str, tuple[str, ...]] = {
    "occupied": ("/map/occupied",),
    "frontier": ("/map/frontier",),
    "unknown": ("/map/unknown",),
    "empty": ("/map/empty",),
    "ellipsoids": ("/ellipsoids",),
    "gmm": ("/gmm",),
    "candidates": ("/candidates",),
    "nbv": ("/nbv", "/selected", "/tour"),
    "views": ("/views",),
    "bbox": ("/context/bbox",),
    "sectors": ("/context/sectors",),
    "cloud": ("/cloud",),
    "turntable": ("/context/turntable",),
    "mesh": ("/context/mesh",),
    "surface": ("/surface",),
    "clusters": ("/clusters",),
    "gizmo": ("/override",),
    "reach": ("/reach",),
    "path": ("/path",),
}
GROUPS: dict[str, str | None] = {
    "/map": None,
    "/context": None,
    "/ellipsoids": "ellipsoids",
    "/gmm": "gmm",
    "/views": "views",
    "/cloud": "cloud",
    "/context/sectors": "sectors",
    "/override": "gizmo",
    "/clusters": "clusters",
    "/tour": "nbv",
    "/reach": "reach",
    "/path": "path",
}
"""Group nodes (empty frames) and the layer that hides them (None: always shown)."""

COLORS: dict[str, tuple[int, int, int]] = {
    "occupied": (45, 85, 200),
    "frontier": (235, 80, 35),
    "unknown": (190, 190, 205),
    "empty": (140, 215, 140),
    "ellipsoid_occupied": (40, 110, 255),
    "ellipsoid_frontier": (255, 40, 40),
    "gmm_occupied": (20, 40, 140),
    "gmm_frontier": (140, 20, 20),
    "nbv": (255, 150, 0),
    "selected": (230, 0, 200),
    "tour": (0, 150, 190),
    "view": (60, 60, 70),
    "bbox": (30, 30, 30),
    "sector": (130, 60, 200),
    "cloud": (20, 20, 20),
    "plate": (205, 195, 180),
    "mesh": (200, 170, 120),
    "surface": (120, 160, 205),
    "custom_ok": (0, 170, 70),
    "custom_bad": (220, 0, 0),
    "path": (0, 205, 255),
}


def colormap(values: NDArray[np.float64], lo: float | None = None, hi: float | None = None) -> NDArray[np.uint8]:
    """(N,) values -> (N, 3) uint8 viridis colours, normalised to [lo, hi] (default: the values' range)."""
    v = np.asarray(values, dtype=np.float64)
    if v.size == 0:
        return np.zeros((0, 3), dtype=np.uint8)
    finite = v[np.isfinite(v)]
    if lo is None:
        lo = float(finite.min()) if finite.size else 0.0
    if hi is None:
        hi = float(finite.max()) if finite.size else 1.0
    t = np.zeros_like(v) if hi <= lo else np.clip((v - lo) / (hi - lo), 0.0, 1.0)
    t = np.nan_to_num(t, nan=0.0)
    stops = np.asarray(VIRIDIS, dtype=np.float64)
    x = t * (len(stops) - 1)
    i = np.minimum(np.floor(x).astype(int), len(stops) - 2)
    f = (x - i)[:, None]
    return np.round(stops[i] * (1 - f) + stops[i + 1] * f).astype(np.uint8)


SCALE_PERCENTILES = (5.0, 95.0)
"""The candidate colour scale runs from the 5th to the 95th percentile of the eligible scores: one outlier
cannot flatten the rest (scores beyond either end take the end colour)."""


def candidate_colors(scores: Sequence[float], eligible: Sequence[bool]) -> tuple[NDArray[np.uint8], float, float]:
    """Colours of the candidate markers: viridis over the eligible scores' 5th..95th percentile, grey for
    ineligible ones.

    Returns (colours (N, 3) uint8, lo, hi) with [lo, hi] the percentile range the colour bar shows.
    """
    s = np.asarray(scores, dtype=np.float64)
    e = np.asarray(eligible, dtype=bool)
    ref = s[e & np.isfinite(s)] if np.any(e) else s[np.isfinite(s)]
    if ref.size:
        lo, hi = (float(v) for v in np.percentile(ref, SCALE_PERCENTILES))
    else:
        lo, hi = 0.0, 1.0
    colors = colormap(s, lo, hi)
    colors[~e] = INELIGIBLE
    return colors, lo, hi


def box_segments(bbox: BoundingBox) -> NDArray[np.float64]:
    """(12, 2, 3) float64: the edges of an axis-aligned box."""
    lo, hi = bbox.lower, bbox.upper
    corners = np.array([[(hi if (k >> a) & 1 else lo)[a] for a in range(3)] for k in range(8)])
    edges = [(i, i | (1 << a)) for i in range(8) for a in range(3) if not (i >> a) & 1]
    return np.stack([corners[[i, j]] for i, j in edges])


def sector_segments(center: NDArray[np.float64], radius: float, edges: NDArray[np.float64]) -> NDArray[np.float64]:
    """(beta, 2, 3) float64: one radial line on the plate (z = 0) per sector start azimuth (rad)."""
    c = np.array([center[0], center[1], 0.0])
    ends = np.stack([c + radius * np.array([math.cos(a), math.sin(a), 0.0]) for a in edges])
    return np.stack([np.broadcast_to(c, ends.shape), ends], axis=1)


def sector_label_positions(
    center: NDArray[np.float64], radius: float, edges: NDArray[np.float64]
) -> NDArray[np.float64]:
    """(beta, 3) float64: mid-sector points on the plate at ``radius``, for the sector labels."""
    beta = len(edges)
    mids = edges + math.pi / beta
    return np.stack([[center[0] + radius * math.cos(a), center[1] + radius * math.sin(a), 0.0] for a in mids])


def proper_rotation(R: NDArray[np.float64]) -> NDArray[np.float64]:
    """R with its last column flipped when det < 0 (an ellipsoid is symmetric, so the shape is the same)."""
    R = np.array(R, dtype=np.float64)
    if np.linalg.det(R) < 0:
        R[:, 2] = -R[:, 2]
    return R


def ellipsoid_instance(e: Ellipsoid) -> tuple[NDArray[np.float64], NDArray[np.float64], NDArray[np.float64]]:
    """(wxyz (4,), position (3,), per-axis scale (3,)) of a unit sphere scaled into the MVEE ``e``."""
    return Pose(proper_rotation(e.rotation), e.center).wxyz, e.center, e.axes


def gmm_instance(
    e: Ellipsoid, sigmas: float = 2.0
) -> tuple[NDArray[np.float64], NDArray[np.float64], NDArray[np.float64]] | None:
    """(wxyz, position, scale) of the ``sigmas``-sigma ellipsoid of e's Gaussian, or None without one."""
    if e.gmm_mean is None or e.gmm_covariance is None:
        return None
    cov = 0.5 * (e.gmm_covariance + e.gmm_covariance.T)
    w, V = np.linalg.eigh(cov)
    axes = sigmas * np.sqrt(np.clip(w, 1e-12, None))
    return Pose(proper_rotation(V), e.gmm_mean).wxyz, e.gmm_mean, axes


def outward_camera(position: NDArray[np.float64], center: NDArray[np.float64], distance: float) -> NDArray[np.float64]:
    """A point ``distance`` beyond ``position`` on the ray from ``center`` through it (to look back at it)."""
    d = np.asarray(position, dtype=np.float64) - np.asarray(center, dtype=np.float64)
    n = float(np.linalg.norm(d))
    d = np.array([0.0, 0.0, 1.0]) if n < 1e-9 else d / n
    return np.asarray(position, dtype=np.float64) + distance * d
