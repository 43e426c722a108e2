"""The surface's accuracy against the ground-truth mesh, by the shared metric (workbench/evaluation/accuracy.py).

One implementation of precision, recall, F at 2 and 5 mm and chamfer: :func:`workbench.evaluation.accuracy`.
What is the surface's own is how it becomes points: :func:`surface_points` samples it uniformly over its area
(about 0.8 mm apart on the bunny at :data:`SURFACE_SAMPLES`), so a surface and a cloud score on the same footing.
:func:`cloud_accuracy` is the shared metric against a mesh (the ground truth built from it and its samples).
"""

from __future__ import annotations

import numpy as np
import trimesh
from numpy.typing import ArrayLike, NDArray

from workbench.evaluation.accuracy import Accuracy, GroundTruth, accuracy
from workbench.surface.mesh import SurfaceMesh

GROUND_TRUTH_SAMPLES = 20_000
"""Points uniform on the true surface for recall: about 1.7 mm apart on a 0.2 m bunny (area ~0.06 m^2)."""
SURFACE_SAMPLES = 100_000
"""Points sampled from a reconstructed surface to score it: about 0.8 mm apart on the bunny, well below 2 mm."""

Truth = GroundTruth | trimesh.Trimesh
"""A ground truth as the shared module holds it, or a mesh to build one of (its samples drawn with the seed)."""


def ground_truth(truth: Truth, samples: ArrayLike | None = None, *, seed: int = 0) -> GroundTruth:
    """``truth`` as a :class:`GroundTruth`: a mesh with ``samples`` (M, 3), default :data:`GROUND_TRUTH_SAMPLES`
    uniform on it drawn with ``seed``; a GroundTruth as it is."""
    if isinstance(truth, GroundTruth):
        return truth
    from devices.mesh import sample_surface

    if samples is None:
        samples = sample_surface(truth, GROUND_TRUTH_SAMPLES, seed=seed)
    return GroundTruth.of(truth, samples)


def cloud_accuracy(
    points_world: ArrayLike, truth: Truth, ground_truth_samples: ArrayLike | None = None, *, seed: int = 0
) -> Accuracy:
    """The shared :func:`workbench.evaluation.accuracy` of a cloud (N, 3) against ``truth``.

    ValueError for a cloud that is not (N, 3), has no points or non-finite values.
    """
    points = np.asarray(points_world, dtype=np.float64)
    if points.ndim == 2 and len(points) == 0:
        raise ValueError("points_world: no points to score")
    return accuracy(ground_truth(truth, ground_truth_samples, seed=seed), points)


def surface_points(surface: SurfaceMesh, n: int = SURFACE_SAMPLES, seed: int = 0) -> NDArray[np.float64]:
    """(n, 3) float64 points uniform over the area of ``surface``, reproducible for ``seed``."""
    if surface.triangles == 0:
        raise ValueError("surface: empty (no triangles) - nothing to sample")
    sampled = trimesh.sample.sample_surface(surface.to_trimesh(), int(n), seed=np.random.default_rng(seed))[0]
    return np.asarray(sampled, dtype=np.float64)


def surface_accuracy(
    surface: SurfaceMesh,
    truth: Truth,
    ground_truth_samples: ArrayLike | None = None,
    *,
    n_points: int | None = None,
    seed: int = 0,
) -> Accuracy:
    """The shared :class:`Accuracy` of a reconstructed surface: of ``n_points`` sampled on it (seed ``seed``);
    None: the truth's ``surface_points`` when it is a :class:`GroundTruth` that has them, else :data:`SURFACE_SAMPLES`."""
    if n_points is None:
        given = truth.surface_points if isinstance(truth, GroundTruth) else None
        n_points = SURFACE_SAMPLES if given is None else given
    return cloud_accuracy(surface_points(surface, n_points, seed), truth, ground_truth_samples, seed=seed)
