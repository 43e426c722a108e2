"""Is a custom camera pose inside (or against) the object? The rule an override must pass besides reach.

A person can drag the gizmo anywhere, so an override is refused when its camera
centre ``c`` is

1. inside the object as far as it has been seen: inside the convex hull of the
   occupied voxel centres grown by one voxel (``resolution``), or
2. nearer than ``standoff`` (the camera's minimum range, ``camera.min_depth``) to
   any point of the accumulated cloud: the camera would touch the object or see
   nothing there.

Rule 1 also refuses a camera in a concavity of the seen surface (the inside of a
mug): such a view is almost always a collision. Before the first frame nothing is
known, so nothing is refused. The hull is computed once per map (the caller caches
:class:`ObjectRegion`).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray
from scipy.spatial import ConvexHull, KDTree


@dataclass(frozen=True, eq=False)
class ObjectRegion:
    """The seen object: hull half-spaces of the occupied voxels (grown) and a tree over the cloud.

    equations: (F, 4) rows (n, d) with n . x + d <= margin inside (unit n), or None (too few / flat voxels:
    then the grown axis-aligned box of the occupied voxels is used, ``lower`` / ``upper``).
    """

    equations: NDArray[np.float64] | None
    lower: NDArray[np.float64] | None
    upper: NDArray[np.float64] | None
    margin: float
    tree: KDTree | None

    @staticmethod
    def build(occupied_centers: NDArray[np.float64], cloud: NDArray[np.float64], resolution: float) -> ObjectRegion:
        occ = np.asarray(occupied_centers, dtype=np.float64).reshape(-1, 3)
        pts = np.asarray(cloud, dtype=np.float64).reshape(-1, 3)
        equations = lower = upper = None
        if len(occ) >= 4:
            try:
                equations = ConvexHull(occ).equations
            except Exception:  # QhullError: coplanar or degenerate voxels -> the box below
                equations = None
        if len(occ) and equations is None:
            lower, upper = occ.min(axis=0), occ.max(axis=0)
        return ObjectRegion(equations, lower, upper, float(resolution), KDTree(pts) if len(pts) else None)

    def inside_reason(self, position: NDArray[np.float64], standoff: float) -> str | None:
        """Why a camera centred at ``position`` (3,) is inside or against the object, or None when it is clear."""
        c = np.asarray(position, dtype=np.float64).reshape(3)
        if self.equations is not None:
            if np.all(self.equations[:, :3] @ c + self.equations[:, 3] <= self.margin):
                return "inside the object: the camera centre lies within the occupied voxels' hull"
        elif (
            self.lower is not None
            and self.upper is not None
            and np.all(c >= self.lower - self.margin)
            and np.all(c <= self.upper + self.margin)
        ):
            return "inside the object: the camera centre lies within the occupied voxels' box"
        if self.tree is not None and standoff > 0:
            distance, _ = self.tree.query(c, k=1)
            if distance < standoff:
                return (
                    f"too close to the object: {distance:.3f} m from the scanned surface, "
                    f"nearer than the camera's minimum range {standoff:.3f} m"
                )
        return None
