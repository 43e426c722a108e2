"""The coverage ceiling of a cell: the union of every reachable candidate view.

No planner can cover more than this in the same cell with the same candidate
hemisphere: the plate hides the bottom and the arm cannot reach every view.
"""

from __future__ import annotations

from dataclasses import replace
from typing import Any

import numpy as np
from numpy.typing import NDArray
from scipy.spatial import KDTree

from planner import Planner
from planner.candidates import propose_candidates
from planner.preprocess import preprocess
from planner.types import DepthFrame


def reachable_coverage(
    cell: Any,
    planner: Planner,
    surface_samples: NDArray[np.float64],
    radius: float = 0.005,
) -> float:
    """Coverage of the union of all reachable candidates of the planner's final hemisphere.

    cell: a simulated cell (``cell.camera.render(T_world_camera)`` gives noise-free depth)
    with ``is_reachable``. surface_samples: (M, 3) ground-truth points.
    """
    bbox = planner.voxel_map.bbox
    if bbox is None or len(surface_samples) == 0:
        return 0.0
    cfg = planner.config
    candidates, _, _ = propose_candidates(bbox, cfg.candidates, cfg.partitions)
    clean = replace(cfg.preprocess, outlier_min_neighbors=0)
    covered = np.zeros(len(surface_samples), dtype=bool)
    set_box = getattr(cell, "set_object_box", None)
    if callable(set_box):
        set_box(bbox)  # the arm keeps clear of the final box, as during the scan
    for cand in candidates:
        if not cell.is_reachable(cand.T_world_camera):
            continue
        depth = cell.camera.render(cand.T_world_camera)
        frame = DepthFrame(depth, cand.T_world_camera, cell.camera.intrinsics)
        points = preprocess(frame.points_world, None, clean)  # down-sampled like the planner's cloud
        if len(points) == 0:
            continue
        todo = np.flatnonzero(~covered)
        if len(todo) == 0:
            break
        dist, _ = KDTree(points).query(surface_samples[todo], k=1, distance_upper_bound=radius)
        covered[todo[np.isfinite(dist)]] = True
    return float(covered.mean())
