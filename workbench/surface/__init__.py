"""The reconstructed surface of a scan: TSDF fusion of the registered depth frames (open3d, CPU), marching cubes,
the plate cut away; a watertight option (screened Poisson, the bottom closed on the plate plane); simplification
for the browser, export to PLY / OBJ / GLB; its accuracy against the ground-truth mesh.

- :class:`SurfaceIntegrator` ``(config, box)``: ``integrate(frame)`` after each capture, ``mesh()`` extracts;
  :func:`reconstruct` ``(frames, config, box)`` at once (a rebuild: the same frames give the same surface);
- :class:`SurfaceMesh`: the value (vertices, faces in canonical order; area, volume, watertight);
- :func:`simplify` ``(surface, max_triangles)``, :func:`layer_bytes`, :func:`export_bytes` ``(surface, fmt)``;
- :func:`surface_accuracy`, :func:`cloud_accuracy` -> :class:`Accuracy` (F-score at 2 and 5 mm, chamfer);
- :func:`surface_block`: the ``surface`` block of a scan's metrics.json.
"""

from workbench.surface.config import SurfaceConfig, SurfaceMethod
from workbench.surface.export import EXPORT_FORMATS, LAYER_TRIANGLES, ExportFormat, export_bytes, layer_bytes, simplify
from workbench.surface.integrator import SurfaceIntegrator, reconstruct
from workbench.surface.mesh import SurfaceError, SurfaceMesh
from workbench.surface.report import surface_block
from workbench.surface.scoring import Accuracy, cloud_accuracy, surface_accuracy
from workbench.surface.watertight import watertight

__all__ = [
    "EXPORT_FORMATS",
    "LAYER_TRIANGLES",
    "Accuracy",
    "ExportFormat",
    "SurfaceConfig",
    "SurfaceError",
    "SurfaceIntegrator",
    "SurfaceMesh",
    "SurfaceMethod",
    "cloud_accuracy",
    "export_bytes",
    "layer_bytes",
    "reconstruct",
    "simplify",
    "surface_accuracy",
    "surface_block",
    "watertight",
]
