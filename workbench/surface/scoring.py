"""Accuracy of a reconstruction against the ground-truth mesh: precision, recall, F-score at 2 and 5 mm, chamfer.

Precision at tau is the fraction of the reconstruction's points within tau of the true surface (exact
point-to-mesh distance, open3d ray casting); recall at tau the fraction of points uniform on the true
surface (:func:`devices.mesh.sample_surface`) within tau of a reconstruction point; the F-score their
harmonic mean. The chamfer distance is the mean of the two directions' mean distances, in millimetres.

A surface is scored on points sampled uniformly over its area (:func:`surface_accuracy`), a cloud on its
own points (:func:`cloud_accuracy`), so the two are comparable. ``cloud_accuracy`` is the one name the
shared accuracy module (``workbench/evaluation/accuracy.py``) replaces when it lands.
"""

from __future__ import annotations

from dataclasses import asdict, dataclass
from typing import Any

import numpy as np
import trimesh
from numpy.typing import ArrayLike, NDArray
from scipy.spatial import KDTree

from workbench.surface.mesh import SurfaceMesh

GROUND_TRUTH_SAMPLES = 20_000
"""Points uniform on the true surface for recall: about 1.7 mm apart on a 0.2 m bunny (area ~0.06 m^2)."""
SURFACE_SAMPLES = 100_000
"""Points sampled from a reconstructed surface to score it: about 0.8 mm apart on the bunny, well below 2 mm."""


@dataclass(frozen=True)
class Accuracy:
    """Precision, recall and F-score at 2 and 5 mm (fractions in [0, 1]) and the chamfer distance (mm)."""

    precision_2mm: float
    recall_2mm: float
    fscore_2mm: float
    precision_5mm: float
    recall_5mm: float
    fscore_5mm: float
    chamfer_mm: float

    def to_json(self) -> dict[str, Any]:
        return asdict(self)


def _fscore(precision: float, recall: float) -> float:
    return 0.0 if precision + recall == 0 else 2.0 * precision * recall / (precision + recall)


def distance_to_mesh(points_world: ArrayLike, mesh: trimesh.Trimesh) -> NDArray[np.float64]:
    """(N,) float64 unsigned distance of each point (N, 3) to the nearest point of ``mesh``'s triangles."""
    import open3d as o3d

    scene = o3d.t.geometry.RaycastingScene()
    vertices = np.ascontiguousarray(mesh.vertices, dtype=np.float32)
    faces = np.ascontiguousarray(mesh.faces, dtype=np.uint32)
    scene.add_triangles(o3d.core.Tensor.from_numpy(vertices), o3d.core.Tensor.from_numpy(faces))
    query = o3d.core.Tensor.from_numpy(np.ascontiguousarray(points_world, dtype=np.float32))
    return scene.compute_distance(query).numpy().astype(np.float64)


def cloud_accuracy(
    points_world: ArrayLike,
    ground_truth: trimesh.Trimesh,
    ground_truth_samples: ArrayLike | None = None,
    *,
    seed: int = 0,
) -> Accuracy:
    """The :class:`Accuracy` of a point cloud against the true surface.

    points_world: (N, 3) float64, N >= 1, finite. ground_truth: the object's mesh in the same frame.
    ground_truth_samples: (M, 3) points uniform on it for recall (default
    :data:`GROUND_TRUTH_SAMPLES` drawn with ``seed``). ValueError for an empty or non-finite cloud.
    """
    from devices.mesh import sample_surface

    points = np.asarray(points_world, dtype=np.float64)
    if points.ndim != 2 or points.shape[1] != 3:
        raise ValueError(f"points_world: expected shape (N, 3), got {points.shape}")
    if len(points) == 0:
        raise ValueError("points_world: no points to score")
    if not np.all(np.isfinite(points)):
        raise ValueError("points_world: non-finite values")
    if ground_truth_samples is None:
        samples = sample_surface(ground_truth, GROUND_TRUTH_SAMPLES, seed=seed)
    else:
        samples = np.asarray(ground_truth_samples, dtype=np.float64)
    to_truth = distance_to_mesh(points, ground_truth)
    to_points, _ = KDTree(points).query(samples, k=1)
    values: dict[str, float] = {}
    for tau_mm in (2, 5):
        tau = tau_mm / 1000.0
        precision = float(np.mean(to_truth <= tau))
        recall = float(np.mean(to_points <= tau))
        values[f"precision_{tau_mm}mm"] = precision
        values[f"recall_{tau_mm}mm"] = recall
        values[f"fscore_{tau_mm}mm"] = _fscore(precision, recall)
    chamfer_mm = 500.0 * (float(np.mean(to_truth)) + float(np.mean(to_points)))
    return Accuracy(chamfer_mm=chamfer_mm, **values)


def surface_points(surface: SurfaceMesh, n: int = SURFACE_SAMPLES, seed: int = 0) -> NDArray[np.float64]:
    """(n, 3) float64 points uniform over the area of ``surface``, reproducible for ``seed``."""
    if surface.triangles == 0:
        raise ValueError("surface: empty (no triangles) - nothing to sample")
    sampled = trimesh.sample.sample_surface(surface.to_trimesh(), int(n), seed=np.random.default_rng(seed))[0]
    return np.asarray(sampled, dtype=np.float64)


def surface_accuracy(
    surface: SurfaceMesh,
    ground_truth: trimesh.Trimesh,
    ground_truth_samples: ArrayLike | None = None,
    *,
    n_points: int = SURFACE_SAMPLES,
    seed: int = 0,
) -> Accuracy:
    """The :class:`Accuracy` of a reconstructed surface: :func:`cloud_accuracy` of ``n_points`` sampled on it."""
    return cloud_accuracy(surface_points(surface, n_points, seed), ground_truth, ground_truth_samples, seed=seed)
