"""How long each frontier voxel has stayed frontier, and per-ellipsoid weights from it (``zbuffer.frontier_decay``).

A frontier voxel that is still FRONTIER after the camera has been pointed at the frontier again
and again is often one no view can clear (a deep concavity, the base on the plate). Here such voxels
are weighed down: a voxel's weight is ``decay ** age``, ``age`` = new frames through which it stayed
FRONTIER, and a frontier ellipsoid weighs the mean of the frontier voxels inside it.

The age advances once per new frame, not per ``plan`` call: a call on an unchanged voxel map
(a re-plan of the same view) leaves every age as it was.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np
from numpy.typing import NDArray

from planner.types import Ellipsoid, VoxelClass
from planner.voxel_map import VoxelMap


def _lattice_keys(centers_world: NDArray[np.float64], resolution: float) -> NDArray[np.int64]:
    """(N,) int64 key of each voxel's global lattice index (21 bits per axis)."""
    idx = np.floor(centers_world / resolution).astype(np.int64) + (1 << 20)
    return (idx[:, 0] << 42) | (idx[:, 1] << 21) | idx[:, 2]


class FrontierAge:
    """Tracks, across the plans of one scan, how many new frames each frontier voxel has stayed frontier."""

    def __init__(self) -> None:
        self._keys = np.zeros(0, dtype=np.int64)  # sorted
        self._ages = np.zeros(0, dtype=np.int64)
        self._frames = -1

    def reset(self) -> None:
        """Forget every age (a new scan)."""
        self.__init__()

    def update_map(self, voxel_map: VoxelMap) -> tuple[NDArray[np.float64], NDArray[np.int64]]:
        """Frontier voxel centres (N, 3) of ``voxel_map`` and their ages (N,)."""
        centers = voxel_map.centers(VoxelClass.FRONTIER)
        return centers, self.update(centers, voxel_map.resolution, voxel_map.frames)

    def update(self, centers_world: NDArray[np.float64], resolution: float, frames: int) -> NDArray[np.int64]:
        """(N,) ages of the frontier voxels with centres ``centers_world`` (N, 3) after ``frames`` frames.

        A voxel that was frontier at the last update and ``frames`` has grown is one older; one that was
        not is 0; with ``frames`` unchanged (a re-plan) the ages are those of the last update.
        """
        keys = _lattice_keys(np.asarray(centers_world, dtype=np.float64).reshape(-1, 3), resolution)
        previous = np.full(len(keys), -1, dtype=np.int64)  # -1: not frontier at the last update
        if len(self._keys):
            pos = np.minimum(np.searchsorted(self._keys, keys), len(self._keys) - 1)
            known = self._keys[pos] == keys
            previous[known] = self._ages[pos[known]]
        ages = previous + 1 if frames != self._frames else np.maximum(previous, 0)
        order = np.argsort(keys)
        self._keys, self._ages, self._frames = keys[order], ages[order], frames
        return ages


def ellipsoid_weights(
    ellipsoids: Sequence[Ellipsoid], centers_world: NDArray[np.float64], voxel_weights: NDArray[np.float64]
) -> NDArray[np.float64]:
    """(E,) mean ``voxel_weights`` (N,) of the voxels (N, 3) inside each frontier ellipsoid; 1 for the others
    and for an ellipsoid that holds none of them."""
    out = np.ones(len(ellipsoids))
    for k, e in enumerate(ellipsoids):
        if e.kind != "frontier" or len(centers_world) == 0:
            continue
        inside = e.contains(centers_world, tol=1e-9)
        if np.any(inside):
            out[k] = float(voxel_weights[inside].mean())
    return out
