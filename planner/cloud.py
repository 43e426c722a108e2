"""The accumulated cloud when some frames were taken while the cell moved: a view's points over a move frame's.

A view is measured with the camera still; a frame taken during a move may be blurred by the exposure and posed a
little late (its stamp against the joint states), so its points lie a few millimetres off where a view's lie. Both
carve the voxel map alike (coverage, the plans), but the cloud, which is the scan's product and the registration's
target, keeps a move frame's points only where no view has measured the surface:

- a move frame's point within ``radius`` of a view's point is left out;
- a view's points take out the move frames' points within ``radius`` of them (the view measured that surface);
- in a down-sampling cell holding both, the centroid is the view points' alone.

So where the views saw the surface the cloud is what stop-and-go would have made of those views, and the move
frames fill in what no view saw. Measured in docs/experiments/move-capture.md.
"""

from __future__ import annotations

import numpy as np
from numpy.typing import NDArray
from scipy.spatial import KDTree

from planner.preprocess import voxel_downsample


def _within(reference: NDArray[np.float64], points: NDArray[np.float64], radius: float) -> NDArray[np.bool_]:
    """(N,) bool: each of ``points`` (N, 3) lies within ``radius`` of some point of ``reference`` (M, 3)."""
    if len(reference) == 0 or len(points) == 0 or radius <= 0:
        return np.zeros(len(points), dtype=bool)
    distance, _ = KDTree(reference).query(points, k=1, distance_upper_bound=radius)
    return np.asarray(distance <= radius)


def _cells(points: NDArray[np.float64], size: float) -> NDArray[np.int64]:
    """(N,) int64 keys of the lattice cells ``floor(p / size)`` of :func:`planner.preprocess.voxel_downsample`
    (21 bits an axis: unique within a cube 2**20 cells wide about the origin, kilometres at any sensible size)."""
    cells = np.floor(points / size).astype(np.int64) + (1 << 20)
    cells = np.clip(cells, 0, (1 << 21) - 1)
    return (cells[:, 0] << 42) | (cells[:, 1] << 21) | cells[:, 2]


def merge_cloud(
    cloud: NDArray[np.float64],
    from_move: NDArray[np.bool_],
    points: NDArray[np.float64],
    move_frame: bool,
    size: float,
    radius: float,
) -> tuple[NDArray[np.float64], NDArray[np.bool_]]:
    """The cloud after adding one frame's ``points``, and which of its points came from move frames only.

    cloud: (K, 3) the accumulated cloud; from_move: (K,) bool, its points that only move frames measured;
    points: (N, 3) the frame's points (world, registered); move_frame: the frame was taken during a move;
    size: the down-sampling cell edge (0: none); radius: a view's points replace the move frames' within this
    distance, metres (0: only within a shared cell). Returns ((K', 3), (K',) bool). Without move frames it is
    ``voxel_downsample`` of the concatenation, as before move frames existed.
    """
    cloud = np.asarray(cloud, dtype=np.float64).reshape(-1, 3)
    from_move = np.asarray(from_move, dtype=bool).reshape(-1)
    points = np.asarray(points, dtype=np.float64).reshape(-1, 3)
    if len(from_move) != len(cloud):
        raise ValueError(f"from_move: one flag per cloud point ({len(cloud)}), got {len(from_move)}")
    if move_frame:
        points = points[~_within(cloud[~from_move], points, radius)]
    elif np.any(from_move):
        stale = np.zeros(len(cloud), dtype=bool)
        stale[from_move] = _within(points, cloud[from_move], radius)
        cloud, from_move = cloud[~stale], from_move[~stale]
    still = np.concatenate([cloud[~from_move], points]) if not move_frame else cloud[~from_move]
    moving = np.concatenate([cloud[from_move], points]) if move_frame else cloud[from_move]
    if size > 0:
        still, moving = voxel_downsample(still, size), voxel_downsample(moving, size)
        if len(still) and len(moving):  # a cell with a view's points keeps those alone
            moving = moving[~np.isin(_cells(moving, size), _cells(still, size))]
    merged = np.concatenate([still, moving])
    return merged, np.concatenate([np.zeros(len(still), dtype=bool), np.ones(len(moving), dtype=bool)])
