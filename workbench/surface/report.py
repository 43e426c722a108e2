"""The ``surface`` block of a scan's metrics.json: the final surface's accuracy, size and time; and the surface
after each view (:class:`ViewSurfaces`), scored once the ground truth is known (:meth:`ViewSurfaces.scored`)."""

from __future__ import annotations

import time
from typing import Any

import trimesh
from numpy.typing import ArrayLike

from planner import DepthFrame
from workbench.surface.integrator import SurfaceIntegrator
from workbench.surface.mesh import SurfaceError, SurfaceMesh
from workbench.surface.scoring import Truth, ground_truth, surface_accuracy

SCORES = ("fscore_2mm", "fscore_5mm", "precision_5mm", "recall_5mm", "chamfer_mm")
"""The accuracy fields of the block (None without a ground truth)."""


def surface_block(
    integrator: SurfaceIntegrator,
    ground_truth: Truth | None,
    ground_truth_samples: ArrayLike | None = None,
) -> tuple[SurfaceMesh | None, dict[str, Any]]:
    """(the final surface, its block) after a scan fed every frame to ``integrator``.

    The block: ``fscore_2mm``, ``fscore_5mm``, ``precision_5mm``, ``recall_5mm``, ``chamfer_mm`` (None without
    a ``ground_truth``, e.g. a real object), ``triangles``, ``seconds`` (every integrate plus the extraction),
    ``method``, ``voxel_size``, ``frames``. When there is no surface (no frame saw the object), the surface is
    None and the block says why in ``error`` with 0 triangles.
    """
    t0 = time.perf_counter()
    block: dict[str, Any] = dict.fromkeys(SCORES)
    block |= {"method": integrator.config.method, "voxel_size": integrator.config.voxel_size}
    block["frames"] = integrator.frames
    try:
        surface = integrator.mesh()
    except SurfaceError as exc:
        return None, block | {"triangles": 0, "seconds": sum(integrator.seconds), "error": str(exc)}
    seconds = sum(integrator.seconds) + time.perf_counter() - t0
    if ground_truth is not None:
        accuracy = surface_accuracy(surface, ground_truth, ground_truth_samples)
        block |= {key: getattr(accuracy, key) for key in SCORES}
    return surface, block | {"triangles": surface.triangles, "seconds": seconds}


class ViewSurfaces:
    """The surface after each view of a scan: :meth:`add` fuses a registered frame into ``integrator`` and keeps the
    surface extracted then (None while no view saw the object), for the per-view score of metrics.json."""

    def __init__(self, integrator: SurfaceIntegrator) -> None:
        self.integrator = integrator
        self.meshes: list[SurfaceMesh | None] = []

    def add(self, frame: DepthFrame) -> None:
        self.integrator.integrate(frame)
        try:
            self.meshes.append(self.integrator.mesh())
        except SurfaceError:
            self.meshes.append(None)

    def scored(self, truth: trimesh.Trimesh) -> tuple[SurfaceMesh | None, dict[str, Any], list[float | None]]:
        """(the final surface, its :func:`surface_block` against ``truth``, F@5mm of each view's surface: None for a
        view with no surface). The truth is sampled once, and the last view's surface, which is the final one, is
        scored once: its F@5mm is the block's."""
        reference = ground_truth(truth)
        surface, block = surface_block(self.integrator, reference)
        earlier = [None if m is None else surface_accuracy(m, reference).fscore_5mm for m in self.meshes[:-1]]
        return surface, block, [*earlier, block["fscore_5mm"]] if self.meshes else []
