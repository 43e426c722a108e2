"""``SurfaceIntegrator``: TSDF fusion of depth frames (open3d's ``VoxelBlockGrid``, CPU), marching cubes, the plate cut.

Integrate each frame as it is captured (with its registered pose); :meth:`SurfaceIntegrator.mesh` extracts the
surface so far. The same frames in the same order give the same surface, array for array: the TSDF values do not
depend on open3d's threads, and :meth:`SurfaceMesh.canonical` removes the order its hash map emits them in.

Which pixels are fused: those whose point lies in the object's box grown by ``box_margin`` - the box given, or
the bounds of every frame's points above the plate inside the workspace cylinder. The plate top within that
footprint is fused too (its TSDF averages the noise of a real sensor flat; the cut at ``plate_clearance``
removes it afterwards, not pixel by pixel), the rest of the plate and the room are not.
"""

from __future__ import annotations

import time
from collections.abc import Iterable

import numpy as np
from numpy.typing import NDArray

from planner.types import BoundingBox, DepthFrame
from workbench.surface.config import SurfaceConfig
from workbench.surface.mesh import SurfaceError, SurfaceMesh

BLOCK_RESOLUTION = 16
"""Voxels per block edge of the sparse grid (open3d's default)."""
INITIAL_BLOCKS = 2_000
"""Blocks allocated up front; open3d's hash map grows past it on demand."""


class SurfaceIntegrator:
    """The incremental surface of one scan.

    config: the settings (:class:`SurfaceConfig`). box: the object's box in the world frame, if known (else
    it grows with the frames' points above the plate).
    """

    def __init__(self, config: SurfaceConfig | None = None, box: BoundingBox | None = None) -> None:
        self.config = config if config is not None else SurfaceConfig()
        self._fixed_box = box
        self._lower: NDArray[np.float64] | None = None if box is None else box.lower.copy()
        self._upper: NDArray[np.float64] | None = None if box is None else box.upper.copy()
        self._grid: object | None = None
        self._support = np.zeros(0, dtype=np.int64)  # keys of the voxels that hold a fused point above the plate
        self._cached: SurfaceMesh | None = None
        self.frames = 0
        """Frames integrated so far."""
        self.seconds: list[float] = []
        """Wall time of each :meth:`integrate`."""

    @property
    def box(self) -> BoundingBox | None:
        """The object's box the cut uses (before ``box_margin``), None before any point above the plate."""
        if self._lower is None or self._upper is None:
            return None
        return BoundingBox(self._lower, self._upper)

    def integrate(self, frame: DepthFrame) -> None:
        """Fuse one frame (its ``T_world_camera`` is the registered pose).

        SurfaceError (the integrator unchanged) for a frame that is not a DepthFrame, or a non-finite or
        improper pose or depth.
        """
        t0 = time.perf_counter()
        if not isinstance(frame, DepthFrame):
            raise SurfaceError(f"frame: expected a DepthFrame, got {type(frame).__name__}")
        T_world_camera = frame.T_world_camera.matrix
        R = T_world_camera[:3, :3]
        if not np.all(np.isfinite(T_world_camera)):
            raise SurfaceError("frame.T_world_camera: non-finite values (NaN or inf)")
        if not np.allclose(R.T @ R, np.eye(3), atol=1e-6) or np.linalg.det(R) < 0:
            raise SurfaceError("frame.T_world_camera: not a proper rotation")
        if not np.all(np.isfinite(frame.depth)):
            raise SurfaceError("frame.depth: non-finite values (NaN or inf)")
        depth, lower, upper, support = self._object_pixels(frame)
        if lower is not None and upper is not None:
            self._fuse(depth, frame, T_world_camera)
            self._lower, self._upper = lower, upper
            self._support = np.union1d(self._support, support)
        self.frames += 1
        self._cached = None
        self.seconds.append(time.perf_counter() - t0)

    def _object_pixels(
        self, frame: DepthFrame
    ) -> tuple[NDArray[np.float32], NDArray[np.float64] | None, NDArray[np.float64] | None, NDArray[np.int64]]:
        """(the depth with pixels outside the grown box zeroed, the box's lower, upper after this frame, the
        voxel keys of its fused points above the plate)."""
        cfg = self.config
        v, u = np.nonzero(frame.depth > 0)
        points_world = frame.points_world  # row-major valid pixels, the order of np.nonzero
        lower, upper = self._lower, self._upper
        if self._fixed_box is None:
            r2 = points_world[:, 0] ** 2 + points_world[:, 1] ** 2
            above = (
                (points_world[:, 2] >= cfg.plate_clearance)
                & (points_world[:, 2] <= cfg.workspace_height)
                & (r2 <= cfg.workspace_radius**2)
            )
            if np.any(above):
                lo, hi = points_world[above].min(axis=0), points_world[above].max(axis=0)
                lower = lo if lower is None else np.minimum(lower, lo)
                upper = hi if upper is None else np.maximum(upper, hi)
        depth = np.zeros_like(frame.depth)
        if lower is None or upper is None:
            return depth, None, None, np.zeros(0, dtype=np.int64)
        m = cfg.box_margin
        inside = np.all((points_world >= lower - m) & (points_world <= upper + m), axis=1)
        if not cfg.fuse_plate:
            inside &= points_world[:, 2] >= cfg.plate_clearance
        depth[v[inside], u[inside]] = frame.depth[v[inside], u[inside]]
        seen = points_world[inside & (points_world[:, 2] >= cfg.plate_clearance)]
        return depth, lower, upper, np.unique(voxel_keys(voxel_indices(seen, cfg.voxel_size)))

    def _fuse(self, depth: NDArray[np.float32], frame: DepthFrame, T_world_camera: NDArray[np.float64]) -> None:
        import open3d as o3d

        cfg = self.config
        if self._grid is None:
            self._grid = o3d.t.geometry.VoxelBlockGrid(
                ("tsdf", "weight"),
                (o3d.core.float32, o3d.core.float32),
                (o3d.core.SizeVector([1]), o3d.core.SizeVector([1])),
                cfg.voxel_size,
                BLOCK_RESOLUTION,
                INITIAL_BLOCKS,
                o3d.core.Device("CPU:0"),
            )
        grid = self._grid
        assert isinstance(grid, o3d.t.geometry.VoxelBlockGrid)
        k = frame.intrinsics
        K = o3d.core.Tensor.from_numpy(np.array([[k.fx, 0.0, k.cx], [0.0, k.fy, k.cy], [0.0, 0.0, 1.0]]))
        T_camera_world = o3d.core.Tensor.from_numpy(np.ascontiguousarray(np.linalg.inv(T_world_camera)))
        image = o3d.t.geometry.Image(o3d.core.Tensor.from_numpy(np.ascontiguousarray(depth)))
        blocks = grid.compute_unique_block_coordinates(
            image, K, T_camera_world, 1.0, cfg.depth_max, cfg.truncation_voxels
        )
        grid.integrate(blocks, image, K, T_camera_world, 1.0, cfg.depth_max, cfg.truncation_voxels)

    def mesh(self) -> SurfaceMesh:
        """The surface of the frames so far (cached until the next :meth:`integrate`).

        SurfaceError when no frame was integrated, or nothing of the object is left after the plate and box cuts.
        """
        if self._cached is None:
            fused = self.fused_mesh()
            if self.config.method == "poisson":
                from workbench.surface.watertight import watertight

                box = self.box
                assert box is not None  # fused_mesh raised otherwise
                fused = watertight(fused, self.config, box)
            self._cached = fused
        return self._cached

    def fused_mesh(self) -> SurfaceMesh:
        """The TSDF surface (marching cubes) without the plate and what lies outside the object's box."""
        import open3d as o3d

        if self.frames == 0:
            raise SurfaceError("no frames integrated: there is no surface yet")
        box = self.box
        if self._grid is None or box is None:
            raise SurfaceError(f"empty surface: none of the {self.frames} frame(s) saw anything above the plate")
        grid = self._grid
        assert isinstance(grid, o3d.t.geometry.VoxelBlockGrid)
        try:
            legacy = grid.extract_triangle_mesh(self.config.weight_threshold).to_legacy()
            vertices = np.asarray(legacy.vertices, dtype=np.float64)
            faces = np.asarray(legacy.triangles, dtype=np.int64)
        except RuntimeError:  # open3d 0.20 raises on a grid with no zero crossing (it cannot set empty colours)
            vertices, faces = np.zeros((0, 3)), np.zeros((0, 3), dtype=np.int64)
        m = self.config.box_margin
        keep_vertex = (vertices[:, 2] >= self.config.plate_clearance) & np.all(
            (vertices >= box.lower - m) & (vertices <= box.upper + m), axis=1
        )
        if self.config.support_voxels > 0:
            keep_vertex &= self._supported(vertices)
        faces = faces[keep_vertex[faces].all(axis=1)] if len(faces) else faces.reshape(0, 3)
        if len(faces) == 0:
            raise SurfaceError(
                f"empty surface: nothing of the object is left after the plate and box cuts ({self.frames} frame(s))"
            )
        return SurfaceMesh.canonical(vertices, faces)

    def _supported(self, vertices: NDArray[np.float64]) -> NDArray[np.bool_]:
        """(V,) bool: a fused point lies within ``support_voxels`` voxels (per axis) of the vertex's voxel."""
        from scipy import ndimage

        if len(self._support) == 0:
            return np.zeros(len(vertices), dtype=bool)
        r = self.config.support_voxels
        seen = keys_to_indices(self._support)
        origin = seen.min(axis=0) - r
        grid = np.zeros(tuple(seen.max(axis=0) - origin + r + 1), dtype=bool)
        grid[tuple((seen - origin).T)] = True
        grid = ndimage.binary_dilation(grid, structure=np.ones((3, 3, 3), dtype=bool), iterations=r)
        ijk = voxel_indices(vertices, self.config.voxel_size) - origin
        inside = np.all((ijk >= 0) & (ijk < grid.shape), axis=1)
        supported = np.zeros(len(vertices), dtype=bool)
        supported[inside] = grid[tuple(ijk[inside].T)]
        return supported


KEY_OFFSET = 2**20
"""Voxel indices are offset by this before packing 21 bits per axis into one int64 key (+-2.6 km at 2.5 mm)."""


def voxel_indices(points: NDArray[np.float64], voxel_size: float) -> NDArray[np.int64]:
    """(N, 3) int64 indices of the voxels of edge ``voxel_size`` holding ``points`` (N, 3)."""
    return np.floor(points / voxel_size).astype(np.int64)


def voxel_keys(ijk: NDArray[np.int64]) -> NDArray[np.int64]:
    """(N,) int64 keys of voxel indices (N, 3), 21 bits per axis."""
    shifted = ijk + KEY_OFFSET
    return (shifted[:, 0] << 42) | (shifted[:, 1] << 21) | shifted[:, 2]


def keys_to_indices(keys: NDArray[np.int64]) -> NDArray[np.int64]:
    """The voxel indices (N, 3) of :func:`voxel_keys` (N,)."""
    mask = (1 << 21) - 1
    return np.column_stack([(keys >> 42) & mask, (keys >> 21) & mask, keys & mask]) - KEY_OFFSET


def reconstruct(
    frames: Iterable[DepthFrame], config: SurfaceConfig | None = None, box: BoundingBox | None = None
) -> SurfaceMesh:
    """The surface of ``frames`` (registered poses) at once: what a rebuild from the journal computes."""
    integrator = SurfaceIntegrator(config, box)
    for frame in frames:
        integrator.integrate(frame)
    return integrator.mesh()
