"""The reconstructed surface of a scan: TSDF fusion of the registered depth frames (open3d, CPU), marching cubes,
the plate cut away; a watertight option (screened Poisson, the bottom closed on the plate plane); simplification
for the browser, export to PLY / OBJ / GLB; its accuracy against the ground-truth mesh.

- :class:`SurfaceConfig`, :func:`surface_config_for` ``(camera)``: the settings, a real sensor's;
- :class:`SurfaceIntegrator` ``(config, box)``: ``integrate(frame)`` after each capture, ``mesh()`` extracts;
  :func:`reconstruct` ``(frames, config, box)`` at once (a rebuild: the same frames give the same surface);
  :func:`frame_plate_plane`: where the plate lies in a frame at its registered pose (a registration may tilt it);
- :class:`SurfaceMesh`: the value (vertices, faces in canonical order; area, volume, watertight);
- :func:`simplify` ``(surface, max_triangles)``, :func:`layer_bytes`, :func:`export_bytes` ``(surface, fmt)``;
- :func:`surface_accuracy`, :func:`cloud_accuracy`: the shared ``workbench.evaluation.Accuracy`` (F at 2 and 5 mm,
  chamfer) of the surface's points (:func:`surface_points`) or a cloud; :func:`ground_truth` builds the truth once;
- :func:`surface_block`: the ``surface`` block of a scan's metrics.json; :class:`ViewSurfaces`: the surface after
  each view, for its per-view F-score.
"""

from workbench.surface.config import SurfaceConfig, SurfaceMethod, surface_config_for
from workbench.surface.export import (
    EXPORT_FORMATS,
    LAYER_TRIANGLES,
    ExportFormat,
    export_bytes,
    layer_bytes,
    layer_mesh,
    simplify,
)
from workbench.surface.integrator import SurfaceIntegrator, reconstruct
from workbench.surface.mesh import SurfaceError, SurfaceMesh
from workbench.surface.plate import frame_plate_plane
from workbench.surface.report import ViewSurfaces, surface_block
from workbench.surface.scoring import (
    GROUND_TRUTH_SAMPLES,
    cloud_accuracy,
    ground_truth,
    surface_accuracy,
    surface_points,
)
from workbench.surface.watertight import watertight

__all__ = [
    "EXPORT_FORMATS",
    "GROUND_TRUTH_SAMPLES",
    "LAYER_TRIANGLES",
    "ExportFormat",
    "SurfaceConfig",
    "SurfaceError",
    "SurfaceIntegrator",
    "SurfaceMesh",
    "SurfaceMethod",
    "ViewSurfaces",
    "cloud_accuracy",
    "export_bytes",
    "frame_plate_plane",
    "ground_truth",
    "layer_bytes",
    "layer_mesh",
    "reconstruct",
    "simplify",
    "surface_accuracy",
    "surface_block",
    "surface_config_for",
    "surface_points",
    "watertight",
]
