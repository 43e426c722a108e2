"""The ``surface`` block of a scan's metrics.json: the final surface's accuracy, size and time."""

from __future__ import annotations

from typing import Any

import trimesh
from numpy.typing import ArrayLike

from workbench.surface.integrator import SurfaceIntegrator
from workbench.surface.mesh import SurfaceMesh
from workbench.surface.scoring import surface_accuracy


def surface_block(
    integrator: SurfaceIntegrator,
    surface: SurfaceMesh,
    ground_truth: trimesh.Trimesh | None,
    ground_truth_samples: ArrayLike | None = None,
    *,
    seconds: float,
) -> dict[str, Any]:
    """``{"fscore_2mm", "fscore_5mm", "precision_5mm", "recall_5mm", "chamfer_mm", "triangles", "seconds",
    "method", "voxel_size", "frames"}``; the scores are None without a ground truth (a real object).

    seconds: the time spent on the surface (every integrate and the extraction).
    """
    block: dict[str, Any] = dict.fromkeys(("fscore_2mm", "fscore_5mm", "precision_5mm", "recall_5mm", "chamfer_mm"))
    if ground_truth is not None:
        accuracy = surface_accuracy(surface, ground_truth, ground_truth_samples)
        block |= {key: getattr(accuracy, key) for key in block}
    return block | {
        "triangles": surface.triangles,
        "seconds": seconds,
        "method": integrator.config.method,
        "voxel_size": integrator.config.voxel_size,
        "frames": integrator.frames,
    }
