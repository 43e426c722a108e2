"""Cleaning a frame's points before registration and integration (numpy/scipy only).

:func:`preprocess` crops to the bounding box B (or, before B exists, to the
workspace cylinder above the plate), removes the plate, down-samples and drops
statistical outliers. :func:`voxel_downsample` also keeps the accumulated cloud thin.
"""

from __future__ import annotations

import numpy as np
from numpy.typing import ArrayLike, NDArray
from scipy.spatial import KDTree

from planner._validate import checked_array
from planner.config import PreprocessConfig
from planner.types import BoundingBox


def preprocess(points_world: ArrayLike, bbox: BoundingBox | None, config: PreprocessConfig) -> NDArray[np.float64]:
    """The points of one frame that belong to the object.

    points_world: (N, 3) float64, finite (else ValueError).
    bbox: B; points farther than ``config.crop_margin`` outside it are dropped.
    None (first frame): keep points within ``workspace_radius`` of the turntable
    axis and below ``workspace_height``.
    Points below ``plate_clearance`` (the plate) are always dropped. What is left is
    down-sampled to ``config.downsample`` voxels (centroids) *before* the statistical
    outlier removal (``outlier_neighbors``, ``outlier_std``): the same cloud the
    accumulated one would keep, at a fraction of the neighbour-search cost.
    Returns (M, 3) float64, M <= N.
    """
    p = checked_array("points_world", points_world, (None, 3))
    if bbox is not None:
        keep = bbox.contains(p, margin=config.crop_margin)
    else:
        r2 = p[:, 0] ** 2 + p[:, 1] ** 2
        keep = (r2 <= config.workspace_radius**2) & (p[:, 2] <= config.workspace_height)
    keep &= p[:, 2] >= config.plate_clearance
    p = p[keep]
    if config.downsample > 0:
        p = voxel_downsample(p, config.downsample)
    if config.outlier_neighbors > 0:
        p = remove_statistical_outliers(p, config.outlier_neighbors, config.outlier_std)
    return np.array(p, dtype=np.float64)


def remove_statistical_outliers(points: ArrayLike, k: int, std: float) -> NDArray[np.float64]:
    """Drop points whose mean distance to their ``k`` nearest neighbours exceeds mean + ``std`` * std-dev.

    points: (N, 3) float64. The mean and std-dev are over all points' mean
    neighbour distances. With N <= k there are too few neighbours to judge:
    the points are returned unchanged. Returns (M, 3) float64 in input order.
    """
    p = checked_array("points", points, (None, 3))
    if not isinstance(k, int | np.integer) or isinstance(k, bool) or k < 1:
        raise ValueError(f"k: must be an integer >= 1, got {k!r}")
    if not (np.isfinite(std) and std >= 0):
        raise ValueError(f"std: must be >= 0, got {std!r}")
    if len(p) <= k:
        return np.array(p, dtype=np.float64)
    dist, _ = KDTree(p).query(p, k=int(k) + 1)  # the first neighbour is the point itself
    mean_dist = dist[:, 1:].mean(axis=1)
    threshold = mean_dist.mean() + std * mean_dist.std()
    return np.array(p[mean_dist <= threshold], dtype=np.float64)


def voxel_downsample(points: ArrayLike, size: float) -> NDArray[np.float64]:
    """One point per occupied voxel of edge ``size``: the centroid of its points.

    points: (N, 3) float64. Voxels are the cells of the lattice ``floor(p / size)``.
    ``size == 0`` returns a copy unchanged; ``size < 0`` is a ValueError.
    Returns (K, 3) float64, K <= N, ordered by voxel index (deterministic).
    """
    p = checked_array("points", points, (None, 3))
    if not (np.isfinite(size) and size >= 0):
        raise ValueError(f"size: must be >= 0, got {size!r}")
    if size == 0 or len(p) == 0:
        return np.array(p, dtype=np.float64)
    keys = np.floor(p / size).astype(np.int64)
    keys -= keys.min(axis=0)
    dims = keys.max(axis=0) + 1
    if float(np.prod(dims.astype(np.float64))) < 2.0**62:
        flat = np.ravel_multi_index(keys.T, tuple(int(d) for d in dims))
        _, inverse, counts = np.unique(flat, return_inverse=True, return_counts=True)
    else:  # a huge spread of points: unique rows instead of flat indices
        _, inverse, counts = np.unique(keys, axis=0, return_inverse=True, return_counts=True)
    inverse = inverse.ravel()
    sums = np.zeros((len(counts), 3))
    for axis in range(3):
        sums[:, axis] = np.bincount(inverse, weights=p[:, axis], minlength=len(counts))
    return sums / counts[:, None]
