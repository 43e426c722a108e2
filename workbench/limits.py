"""Bounds on a planner config that arrives over the REST API (422 beyond them).

``PlannerConfig`` only refuses values that make no sense (a negative resolution);
a request could still ask for a 1e-9 m voxel grid or a billion candidates and
exhaust the server's memory or time. These bounds are generous for real scans
(the paper's defaults are far inside them) and keep one request from taking the
machine down. The operator's own TOML config is not bounded.
"""

from __future__ import annotations

from planner import PlannerConfig
from workbench.errors import Invalid

MAX_GRID_CELLS_PER_AXIS = 300
"""``voxel.max_extent / voxel.resolution`` at most this: a grid of at most 300^3 = 27 M voxels."""

BOUNDS: dict[str, tuple[float, float]] = {
    "voxel.resolution": (0.001, 0.2),
    "voxel.gamma": (0.0, 0.5),
    "voxel.max_extent": (0.01, 3.0),
    "voxel.initial_diagonal_factor": (1.0, 10.0),
    "cluster.t_max": (1, 200),
    "cluster.max_iter": (1, 1000),
    "candidates.count": (1, 5000),
    "candidates.parallels": (1, 200),
    "candidates.working_distance": (0.01, 5.0),
    "partitions.sectors": (1, 360),
    "termination.max_views": (1, 500),
    "preprocess.outlier_min_neighbors": (0, 200),
    "preprocess.outlier_radius": (0.0, 0.1),
    "preprocess.workspace_radius": (0.0, 5.0),
    "preprocess.workspace_height": (0.0, 5.0),
    "preprocess.crop_margin": (0.0, 1.0),
    "registration.max_iterations": (1, 500),
}
"""Inclusive [low, high] of config fields accepted over the API."""


def check_config(config: PlannerConfig) -> None:
    """Invalid (422) naming the first field outside ``BOUNDS`` or a grid that is too fine."""
    for name, (low, high) in BOUNDS.items():
        section, key = name.split(".")
        value = getattr(getattr(config, section), key)
        if not low <= value <= high:
            raise Invalid(f"config: {name} must be in [{low:g}, {high:g}] over the API, got {value!r}")
    cells = config.voxel.max_extent / config.voxel.resolution
    if cells > MAX_GRID_CELLS_PER_AXIS:
        raise Invalid(
            f"config: voxel.max_extent / voxel.resolution = {cells:.0f} voxels per axis, "
            f"more than {MAX_GRID_CELLS_PER_AXIS} (coarser resolution or smaller max_extent)"
        )
