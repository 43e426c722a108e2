"""Scan quality measured against the ground-truth mesh (simulation only)."""

from __future__ import annotations

import numpy as np
from numpy.typing import ArrayLike
from scipy.spatial import KDTree


def coverage(surface_samples: ArrayLike, cloud: ArrayLike, radius: float = 0.005) -> float:
    """Fraction of ``surface_samples`` with a ``cloud`` point within ``radius`` metres.

    surface_samples: (M, 3) float64, M >= 1, points uniform on the true surface
    (``devices.mesh.sample_surface``). cloud: (N, 3) float64, the scanned points;
    N = 0 gives 0.0. Returns a float in [0, 1]. Non-finite values, bad shapes and
    radius <= 0 raise ValueError.
    """
    samples = as_points("surface_samples", surface_samples)
    points = as_points("cloud", cloud)
    if len(samples) == 0:
        raise ValueError("surface_samples: need at least one sample")
    if not (isinstance(radius, int | float) and np.isfinite(radius) and radius > 0):
        raise ValueError(f"radius: must be > 0, got {radius!r}")
    if len(points) == 0:
        return 0.0
    dist, _ = KDTree(points).query(samples, k=1, distance_upper_bound=radius)
    return float(np.count_nonzero(dist <= radius)) / len(samples)


def as_points(name: str, value: ArrayLike) -> np.ndarray:
    """``value`` as (N, 3) float64 points; ValueError naming ``name`` for another shape or a non-finite value."""
    arr = np.asarray(value, dtype=np.float64)
    if arr.ndim == 1 and arr.size == 0:
        arr = arr.reshape(0, 3)
    if arr.ndim != 2 or arr.shape[1] != 3:
        raise ValueError(f"{name}: expected shape (N, 3), got {arr.shape}")
    if not np.all(np.isfinite(arr)):
        raise ValueError(f"{name}: {int(np.count_nonzero(~np.isfinite(arr)))} non-finite value(s)")
    return arr
