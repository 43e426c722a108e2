"""Growth of the object bounding box B (paper §III-C), as pure functions.

Paper: "B is initialized to the bounding box of V_o in the first frame. Then B is
expanded along the direction of the current viewpoint, doubling the diagonal. In
subsequent updates, a sphere of radius gamma is generated around each frontier
voxel, and B is expanded to cover V_o and the spheres."

Two coordinate systems appear here: world boxes (``BoundingBox``, metres) and
lattice ranges ``(lo, hi)`` of (3,) int64 voxel indices on the global lattice
(voxel ``i`` spans ``[i, i + 1) * resolution``; ``hi`` is exclusive). The voxel map
stores B as a lattice range, so B is always snapped outwards to the lattice.
"""

from __future__ import annotations

import math

import numpy as np
from numpy.typing import ArrayLike, NDArray

from planner.types import BoundingBox
from planner.validate import checked_array

LatticeRange = tuple[NDArray[np.int64], NDArray[np.int64]]

_SNAP_TOL = 1e-9
"""Voxel units: a box face within this of a lattice plane is taken to lie on it (float noise, e.g. 0.1 / 0.01)."""


def union(a: BoundingBox | None, b: BoundingBox | None) -> BoundingBox | None:
    """Smallest box containing both (``None`` is the empty box)."""
    if a is None:
        return b
    if b is None:
        return a
    return BoundingBox(np.minimum(a.lower, b.lower), np.maximum(a.upper, b.upper))


def view_growth_distance(extent: ArrayLike, direction: ArrayLike, factor: float) -> float:
    """Sweep distance s >= 0 so that sweeping a box of ``extent`` (3,) by ``s * d`` scales its diagonal by ``factor``.

    Sweeping by ``s d`` (unit ``d``) turns extent ``e`` into ``e + s |d|``, so
    ``sum (e_i + s |d_i|)^2 = factor^2 |e|^2``: ``s^2 + 2 b s + c = 0`` with
    ``b = e . |d|`` and ``c = (1 - factor^2) |e|^2 <= 0``; the root
    ``s = -c / (b + sqrt(b^2 - c))`` (stable form). A box with zero diagonal gives 0.
    """
    e = checked_array("extent", extent, (3,))
    d = checked_array("direction", direction, (3,))
    if np.any(e < 0):
        raise ValueError(f"extent: must be >= 0, got {e}")
    if not (math.isfinite(factor) and factor >= 1):
        raise ValueError(f"factor: must be >= 1, got {factor!r}")
    n = float(np.linalg.norm(d))
    if n < 1e-12:
        raise ValueError("direction: must be non-zero")
    d = np.abs(d) / n
    d2 = float(e @ e)
    if d2 == 0.0:
        return 0.0
    b = float(e @ d)
    c = (1.0 - factor * factor) * d2
    root = math.sqrt(b * b - c)
    return 0.0 if root + b == 0 else -c / (b + root)


def grow_along_view(box: BoundingBox, direction: ArrayLike, factor: float) -> BoundingBox:
    """``bbox(box ∪ (box + s d))`` for the unit view direction ``d`` (3,) and ``s`` from ``view_growth_distance``.

    The box is extended only on the far side (away from the camera): faces whose
    outward normal has a positive component along ``d`` move by ``s d_i``.
    """
    d = checked_array("direction", direction, (3,))
    s = view_growth_distance(box.extent, d, factor)
    shift = s * d / np.linalg.norm(d)
    return BoundingBox(box.lower + np.minimum(shift, 0.0), box.upper + np.maximum(shift, 0.0))


def lattice_range(box: BoundingBox, resolution: float) -> LatticeRange:
    """Smallest lattice range covering ``box`` (at least one voxel per axis)."""
    lo = np.floor(box.lower / resolution + _SNAP_TOL).astype(np.int64)
    hi = np.ceil(box.upper / resolution - _SNAP_TOL).astype(np.int64)
    return lo, np.maximum(hi, lo + 1)


def index_range(idx: NDArray[np.int64]) -> LatticeRange | None:
    """Lattice range ``[min, max + 1)`` of voxel indices ``idx`` (N, 3); None when N == 0."""
    if idx.shape[0] == 0:
        return None
    # per column: numpy's axis-0 reduction of an (N, 3) array is ~15x slower
    lo = np.array([idx[:, a].min() for a in range(3)], dtype=np.int64)
    hi = np.array([idx[:, a].max() for a in range(3)], dtype=np.int64) + 1
    return lo, hi


def range_union(a: LatticeRange | None, b: LatticeRange | None) -> LatticeRange | None:
    if a is None:
        return b
    if b is None:
        return a
    return np.minimum(a[0], b[0]), np.maximum(a[1], b[1])


def range_box(rng: LatticeRange, resolution: float) -> BoundingBox:
    """World box of a lattice range."""
    return BoundingBox((rng[0] * resolution).astype(np.float64), (rng[1] * resolution).astype(np.float64))


def cap_range(want: LatticeRange, keep: LatticeRange | None, center: ArrayLike, max_voxels: int) -> LatticeRange:
    """Limit every edge of ``want`` to ``max_voxels``, keeping ``keep`` (the current B) inside.

    Where ``want`` is too long, the window of ``max_voxels`` is centred on ``center``
    (3,) (lattice units, e.g. the middle of the occupied voxels) and then shifted as
    little as needed to stay inside ``want`` and to contain ``keep`` (B only grows).
    ``keep`` must lie inside ``want`` and be no longer than ``max_voxels``.
    """
    lo, hi = want[0].copy(), want[1].copy()
    c = np.asarray(center, dtype=np.float64)
    for i in range(3):
        if hi[i] - lo[i] <= max_voxels:
            continue
        start = round(float(c[i]) - max_voxels / 2.0)
        low_bound, high_bound = int(lo[i]), int(hi[i]) - max_voxels
        if keep is not None:
            low_bound = max(low_bound, int(keep[1][i]) - max_voxels)
            high_bound = min(high_bound, int(keep[0][i]))
        start = min(max(start, low_bound), high_bound)
        lo[i], hi[i] = start, start + max_voxels
    return lo, hi


def floor_range(rng: LatticeRange, floor_height: float | None, resolution: float) -> LatticeRange:
    """Raise the bottom of ``rng`` to the voxel layer at ``floor_height`` (None: unchanged).

    Nothing below the turntable plate can be seen, so B (and its frontier) stops there.
    The range keeps at least one layer.
    """
    if floor_height is None:
        return rng
    lo, hi = rng[0].copy(), rng[1].copy()
    lo[2] = max(int(lo[2]), math.floor(floor_height / resolution + _SNAP_TOL))
    hi[2] = max(int(hi[2]), int(lo[2]) + 1)
    return lo, hi


def max_voxels(max_extent: float, resolution: float) -> int:
    """Most voxels per edge that fit in ``max_extent`` (at least 1)."""
    return max(1, math.floor(max_extent / resolution + _SNAP_TOL))
