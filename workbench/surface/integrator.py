"""``SurfaceIntegrator``: TSDF fusion of depth frames (open3d's ``VoxelBlockGrid``, CPU), marching cubes, the plate cut.

Integrate each frame as it is captured (with its registered pose); :meth:`SurfaceIntegrator.mesh` extracts the
surface so far. The same frames in the same order give the same surface, array for array: the TSDF values do not
depend on open3d's threads, and :meth:`SurfaceMesh.canonical` removes the order its hash map emits them in.

Which pixels are fused: those whose point lies in the object's box grown by ``box_margin`` - the box given, or
the bounds of every frame's points above the plate inside the workspace cylinder. The plate top within that
footprint is fused too (its TSDF averages the noise of a real sensor flat; the cut at ``plate_clearance``
removes it afterwards, not pixel by pixel), the rest of the plate and the room are not. "Above the plate" is
above the plate as the frame's registered pose puts it (:func:`workbench.surface.plate.frame_plate_plane`: z = 0
unless a registration tilted the frame); the plate's pixels that such a tilt lifts above the cut are not fused.
"""

from __future__ import annotations

import time
from collections.abc import Iterable

import numpy as np
from numpy.typing import NDArray

from planner.types import BoundingBox, DepthFrame
from workbench.surface.config import SurfaceConfig
from workbench.surface.mesh import SurfaceError, SurfaceMesh
from workbench.surface.plate import frame_plate_plane, plate_height

BLOCK_RESOLUTION = 8
"""Voxels per block edge of the sparse grid (20 mm at 2.5 mm voxels). Open3d's default, 16, allocates twice the
voxels around the +-7.5 mm band the surface lives in (580 000 against 300 000 on the bunny at 10 views): 8 takes a
quarter of the integration's CPU time and 60 % of the extraction's, for the same surface (39 031 against 39 038
triangles, F@5mm 0.9548 against 0.9545); 4 starts to lose triangles (benchmarks/bench_surface_session.py)."""
INITIAL_BLOCKS = 4_000
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
        self._supported_keys = np.zeros(0, dtype=np.int64)  # sorted keys within support_voxels of one of them
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
            self._add_support(support)
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
        points_world = world_points(frame)  # row-major valid pixels, the order of np.nonzero
        z = points_world[:, 2]
        # the plate as this frame's pose puts it (z = 0 unless a registration tilted it: frame_plate_plane); none is
        # fitted before the object's box is known (the first frame's pose is the reported one: nothing to register to)
        box = self.box
        plane = np.zeros(3) if box is None else frame_plate_plane(points_world, cfg, box)
        plate = z < cfg.plate_clearance + (plate_height(plane, points_world) if plane.any() else 0.0)
        lower, upper = self._lower, self._upper
        if self._fixed_box is None:
            r2 = points_world[:, 0] ** 2 + points_world[:, 1] ** 2
            above = ~plate & (z <= cfg.workspace_height) & (r2 <= cfg.workspace_radius**2)
            if np.any(above):
                lo, hi = points_world[above].min(axis=0), points_world[above].max(axis=0)
                lower = lo if lower is None else np.minimum(lower, lo)
                upper = hi if upper is None else np.maximum(upper, hi)
        depth = np.zeros_like(frame.depth)
        if lower is None or upper is None:
            return depth, None, None, np.zeros(0, dtype=np.int64)
        m = cfg.box_margin
        inside = np.all((points_world >= lower - m) & (points_world <= upper + m), axis=1)
        # the plate's pixels are fused where the cut at plate_clearance removes them again, never above it
        inside &= (~plate | (z < cfg.plate_clearance)) if cfg.fuse_plate else ~plate
        depth[v[inside], u[inside]] = frame.depth[v[inside], u[inside]]
        seen = points_world[inside & ~plate]
        return depth, lower, upper, sorted_unique(voxel_keys(voxel_indices(seen, cfg.voxel_size)))

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
            extracted = grid.extract_triangle_mesh(self.config.weight_threshold)
            vertices = extracted.vertex.positions.numpy().astype(np.float64)
            faces = extracted.triangle.indices.numpy().astype(np.int64)
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

    def _add_support(self, keys: NDArray[np.int64]) -> None:
        """Add a frame's seen voxels (sorted unique ``keys`` (K,)) to the support, and their neighbourhood within
        ``support_voxels`` (per axis) to the supported voxels: only the voxels no earlier frame saw are dilated,
        so the filter costs a frame's new voxels, not the whole surface's."""
        new = keys[~sorted_member(keys, self._support)]
        self._support = sorted_unique(np.concatenate([self._support, new]))
        r = self.config.support_voxels
        if r > 0 and len(new):
            grown = (new[:, None] + neighbour_offsets(r)[None, :]).ravel()
            self._supported_keys = sorted_unique(np.concatenate([self._supported_keys, grown]))

    def _supported(self, vertices: NDArray[np.float64]) -> NDArray[np.bool_]:
        """(V,) bool: a fused point lies within ``support_voxels`` voxels (per axis) of the vertex's voxel."""
        return sorted_member(voxel_keys(voxel_indices(vertices, self.config.voxel_size)), self._supported_keys)


KEY_OFFSET = 2**20
"""Voxel indices are offset by this before packing 21 bits per axis into one int64 key (+-2.6 km at 2.5 mm)."""


def voxel_indices(points: NDArray[np.float64], voxel_size: float) -> NDArray[np.int64]:
    """(N, 3) int64 indices of the voxels of edge ``voxel_size`` holding ``points`` (N, 3)."""
    return np.floor(points / voxel_size).astype(np.int64)


def voxel_keys(ijk: NDArray[np.int64]) -> NDArray[np.int64]:
    """(N,) int64 keys of voxel indices (N, 3), 21 bits per axis."""
    shifted = ijk + KEY_OFFSET
    return (shifted[:, 0] << 42) | (shifted[:, 1] << 21) | shifted[:, 2]


def world_points(frame: DepthFrame) -> NDArray[np.float64]:
    """(N, 3) float64 ``frame.points_world`` (its valid pixels, row-major) by nine multiply-adds per point: numpy's
    (N, 3) @ (3, 3) product goes through BLAS, 10x the CPU time (16 ms against 1.5 ms for 70 000 points)."""
    points_camera = frame.points_camera
    R, t = frame.T_world_camera.rotation, frame.T_world_camera.translation
    x, y, z = points_camera[:, 0], points_camera[:, 1], points_camera[:, 2]
    out = np.empty_like(points_camera)
    for i in range(3):
        out[:, i] = R[i, 0] * x + R[i, 1] * y + R[i, 2] * z + t[i]
    return out


def sorted_unique(keys: NDArray[np.int64]) -> NDArray[np.int64]:
    """The sorted distinct values of ``keys`` (N,). ``np.unique`` of numpy 2.4 hashes first: 40x slower on 400 000
    distinct keys (0.36 s against 8 ms for a sort)."""
    s = np.sort(keys)
    keep = np.ones(len(s), dtype=bool)
    np.not_equal(s[1:], s[:-1], out=keep[1:])
    return s[keep]


def sorted_member(keys: NDArray[np.int64], table: NDArray[np.int64]) -> NDArray[np.bool_]:
    """(N,) bool: each of ``keys`` (N,) is in ``table`` (M,), sorted ascending."""
    if len(table) == 0:
        return np.zeros(len(keys), dtype=bool)
    at = np.minimum(np.searchsorted(table, keys), len(table) - 1)
    return table[at] == keys


def neighbour_offsets(r: int) -> NDArray[np.int64]:
    """((2r+1)^3,) int64: what adding each to a voxel's key does to its indices, every (di, dj, dk) in [-r, r]^3
    (the fields do not carry for indices within +-2^20 - r)."""
    d = np.arange(-r, r + 1, dtype=np.int64)
    di, dj, dk = np.meshgrid(d, d, d, indexing="ij")
    return ((di << 42) + (dj << 21) + dk).ravel()


def reconstruct(
    frames: Iterable[DepthFrame], config: SurfaceConfig | None = None, box: BoundingBox | None = None
) -> SurfaceMesh:
    """The surface of ``frames`` (registered poses) at once: what a rebuild from the journal computes."""
    integrator = SurfaceIntegrator(config, box)
    for frame in frames:
        integrator.integrate(frame)
    return integrator.mesh()
