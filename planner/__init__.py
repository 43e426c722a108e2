"""The projection-based next-best-view planner (paper §III), pure numpy/scipy/scikit-learn.

Read top-down against the paper:

- ``types``       value types (Pose, DepthFrame, Ellipsoid, Candidate, ViewScore, PlanResult)
- ``config``      one dataclass per component, the paper's defaults
- ``preprocess``  crop, plate removal, outliers, down-sampling
- ``registration``  point-to-plane ICP with an acceptance gate
- ``raycast``, ``voxel_map``, ``frontier``, ``bbox``   §III-C voxel structure and B's growth
- ``mixture``, ``bic_search``, ``clustering``         §III-D GMM, BIC and the choice of T
- ``mvee``, ``ellipsoids``                             §III-D minimum-volume ellipsoids per cluster
- ``small_linalg``                                     their stacks of 3x3 / 4x4 inverses, bit-identical, faster
- ``fit_quality``                                      how well each ellipsoid fills (debugging a fit by eye)
- ``candidates``                                       §III-B hemisphere of candidate views
- ``projection``, ``scoring``                          §III-E dual quadric -> conic, rank weights, F
- ``partitions``                                       §III-F global longitude partitions
- ``evaluators``, ``planner``                          Algorithm 1
- ``tour``, ``paths``                                   planners of robot time: a tour of views, moves that count the way
- ``progress``                                         where a running plan is (stage k of n), for a caller
- ``deferred_imports``                                 open3d's plotly drawing (dash) imported on use
"""

from typing import TYPE_CHECKING, Any

from planner.config import PlannerConfig
from planner.deferred_imports import defer
from planner.types import (
    BoundingBox,
    CameraPath,
    Candidate,
    ClusterFit,
    DepthFrame,
    Ellipsoid,
    Intrinsics,
    PlanResult,
    Pose,
    TourPlan,
    ViewScore,
    VoxelClass,
    VoxelSnapshot,
    unit_quaternion,
)

defer()  # before any module of ours imports open3d (neither module above does)

if TYPE_CHECKING:
    from planner.planner import IntegrationReport, Planner


def __getattr__(name: str) -> Any:
    """Load the facade lazily, so ``planner.types`` imports stay light."""
    if name in ("Planner", "IntegrationReport"):
        from planner import planner as _planner

        return getattr(_planner, name)
    raise AttributeError(f"module 'planner' has no attribute {name!r}")


__all__ = [
    "BoundingBox",
    "CameraPath",
    "Candidate",
    "ClusterFit",
    "DepthFrame",
    "Ellipsoid",
    "IntegrationReport",
    "Intrinsics",
    "PlanResult",
    "Planner",
    "PlannerConfig",
    "Pose",
    "TourPlan",
    "ViewScore",
    "VoxelClass",
    "VoxelSnapshot",
    "unit_quaternion",
]
