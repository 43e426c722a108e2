"""The watertight option: a screened Poisson surface of the fused surface's points, the unseen bottom closed on
the plate plane (open3d's ``create_from_point_cloud_poisson``)."""

from __future__ import annotations

import numpy as np
from numpy.typing import NDArray
from scipy import ndimage

from planner.types import BoundingBox
from workbench.surface.config import SurfaceConfig
from workbench.surface.mesh import SurfaceError, SurfaceMesh

BASE_BAND = 0.005
"""Fused vertices lower than ``plate_clearance`` + this outline where the object stands on the plate, metres."""


def bottom_points(fused: SurfaceMesh, config: SurfaceConfig) -> NDArray[np.float64]:
    """(B, 3) float64 points on the plate plane z = 0 filling the object's footprint (B may be 0).

    The footprint: the xy cells (``voxel_size``) of the fused vertices in the base band, closed and with their
    holes filled (a ring of wall becomes a disc; two boxes side by side stay two rectangles).
    """
    cell = config.voxel_size
    low = fused.vertices[fused.vertices[:, 2] < config.plate_clearance + BASE_BAND]
    if len(low) == 0:
        return np.zeros((0, 3))
    origin = low[:, :2].min(axis=0) - 2 * cell
    ij = np.floor((low[:, :2] - origin) / cell).astype(np.int64)
    occupied = np.zeros(tuple(ij.max(axis=0) + 3), dtype=bool)
    occupied[ij[:, 0], ij[:, 1]] = True
    footprint = ndimage.binary_fill_holes(ndimage.binary_closing(occupied, iterations=2))
    assert footprint is not None
    cells = np.argwhere(footprint)
    xy = origin + (cells + 0.5) * cell
    return np.column_stack([xy, np.zeros(len(xy))])


def watertight(fused: SurfaceMesh, config: SurfaceConfig, box: BoundingBox) -> SurfaceMesh:
    """A closed surface around ``fused`` (the TSDF surface): screened Poisson of its vertices (normals from its
    faces) and of :func:`bottom_points` (normals down), vertices with support density in the lowest
    ``poisson_density_quantile`` trimmed, then held inside the plate plane and the object's box grown by
    ``box_margin`` (clamped, not cut: clamping keeps it watertight)."""
    import open3d as o3d

    mesh = o3d.geometry.TriangleMesh(
        o3d.utility.Vector3dVector(fused.vertices.copy()), o3d.utility.Vector3iVector(fused.faces.astype(np.int32))
    )
    mesh.compute_vertex_normals()
    bottom = bottom_points(fused, config)
    points = np.concatenate([fused.vertices, bottom])
    normals = np.concatenate([np.asarray(mesh.vertex_normals), np.tile([0.0, 0.0, -1.0], (len(bottom), 1))])
    cloud = o3d.geometry.PointCloud(o3d.utility.Vector3dVector(points))
    cloud.normals = o3d.utility.Vector3dVector(normals)
    with o3d.utility.VerbosityContextManager(o3d.utility.VerbosityLevel.Error):
        closed, densities = o3d.geometry.TriangleMesh.create_from_point_cloud_poisson(
            cloud, depth=config.poisson_depth, n_threads=1
        )
    if config.poisson_density_quantile > 0:
        density = np.asarray(densities)
        closed.remove_vertices_by_mask(density < np.quantile(density, config.poisson_density_quantile))
    vertices = np.asarray(closed.vertices, dtype=np.float64).copy()
    faces = np.asarray(closed.triangles, dtype=np.int64)
    if len(faces) == 0:
        raise SurfaceError("empty surface: the Poisson solve gave no triangles")
    m = config.box_margin
    lower = np.maximum(box.lower - m, [-np.inf, -np.inf, 0.0])
    vertices = np.clip(vertices, lower, box.upper + m)
    return SurfaceMesh.canonical(vertices, faces)
