"""Baseline planners for comparison with the projection evaluator (the ray-casting planners the paper compares against).

Importing this package registers in ``planner.evaluators.EVALUATORS``:

- ``raycast-apora``: APORA object-probability gain (Daudelin & Campbell 2017, Pan's simulator);
- ``raycast-oa``, ``raycast-uv``, ``raycast-rse``: Isler et al. 2016 occlusion aware,
  unobserved voxel, rear side entropy;
- ``random``: a uniformly random eligible candidate, as a floor.

Modules: ``gains`` (the formulas, pure functions on voxel sequences), ``rays``
(candidate rays and batched Amanatides–Woo traversal), ``evaluators`` (the
``ViewEvaluator`` classes).
"""

from planner.baselines.evaluators import (
    BASELINES,
    AporaEvaluator,
    OcclusionAwareEvaluator,
    RandomEvaluator,
    RaycastEvaluator,
    RearSideEntropyEvaluator,
    UnobservedVoxelEvaluator,
    raycast_view_gains,
)
from planner.evaluators import EVALUATORS

EVALUATORS.update(BASELINES)

__all__ = [
    "BASELINES",
    "AporaEvaluator",
    "OcclusionAwareEvaluator",
    "RandomEvaluator",
    "RaycastEvaluator",
    "RearSideEntropyEvaluator",
    "UnobservedVoxelEvaluator",
    "raycast_view_gains",
]
