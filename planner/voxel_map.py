"""The five-class voxel map over the object bounding box B (paper §III-C).

Classes (``VoxelClass``, stored as (X, Y, Z) uint8): NONE (never observed, e.g. just
added by a growth of B), EMPTY, OCCUPIED, UNKNOWN, FRONTIER. EMPTY and OCCUPIED are
final: once set they never change. FRONTIER is derived from UNKNOWN after every frame.

The grid lives on a global lattice: voxel ``(i, j, k)`` of the grid is lattice voxel
``lower_index + (i, j, k)``, spanning ``[n, n + 1) * resolution`` per axis, so growing B
is an index shift and a copy.

One ``integrate(frame, points_world)``:

1. grow B to cover the new points (first frame: B0 = bbox of the voxels of the points,
   then swept along the camera's viewing direction until its diagonal is
   ``initial_diagonal_factor`` times B0's);
2. classify the voxels the frame observed (``observe_projective``, the default, or the
   Amanatides–Woo reference ``planner.raycast.observe_raycast``): a voxel every ray passes
   before its hit becomes EMPTY, one a ray reaches at or after its hit UNKNOWN (final voxels
   are left alone); voxels containing a point become OCCUPIED (occupied wins over empty
   within a frame);
3. recompute FRONTIER;
4. grow B to cover V_o and spheres of radius gamma around the frontier voxels (new voxels NONE).

Every edge of B is capped at ``max_extent`` (see ``bbox.cap_range``: the window is centred
on the occupied voxels and the new points and always contains the previous B); points
outside the capped B are dropped (counted in ``IntegrationStats.n_points_outside``).
Everything is computed into new arrays and swapped in at the end, so an exception leaves
the map unchanged.
"""

from __future__ import annotations

import copy
import time
from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike, NDArray

from planner import bbox as bb
from planner.config import VoxelConfig
from planner.frontier import relabel_frontier
from planner.raycast import EMPTY_EPS, observe_raycast
from planner.types import BoundingBox, DepthFrame, VoxelClass, VoxelSnapshot
from planner.validate import checked_array


@dataclass(frozen=True)
class IntegrationStats:
    """What one ``VoxelMap.integrate`` changed.

    n_new_occupied / n_new_empty: voxels that became OCCUPIED / EMPTY in this frame.
    n_new_unknown: voxels that were NONE and became UNKNOWN or FRONTIER.
    n_frontier: FRONTIER voxels after the frame. n_points_outside: points dropped
    because they lie outside B (only when B hit ``max_extent``). bbox_grew: B changed
    (always True for the first frame). seconds: wall time of the call.
    """

    n_new_occupied: int
    n_new_empty: int
    n_new_unknown: int
    n_frontier: int
    n_points_outside: int
    bbox_grew: bool
    seconds: float


_BROADCAST = ((slice(None), None, None), (None, slice(None), None), (None, None, slice(None)))


def _project(
    frame: DepthFrame, offsets: list[NDArray[np.float64]]
) -> tuple[NDArray[np.float32], NDArray[np.bool_], NDArray[np.float32]]:
    """Project the lattice of points ``camera + (offsets[0][i], offsets[1][j], offsets[2][k])`` into the image.

    offsets: three 1-D arrays of world offsets from the camera centre (the lattice is separable, so camera
    coordinates are sums of three broadcast 1-D terms; float32 is ample: 3e-8 m at 0.5 m).
    Returns ``(z (I, J, K) camera depth, inside (I, J, K) bool: in front of the camera and in the image,
    depth (M,) float32: the depth image at the rounded pixel of each inside point)``.
    """
    T, k = frame.T_world_camera, frame.intrinsics
    Rt = T.rotation.T
    terms = [[(Rt[row, a] * offsets[a]).astype(np.float32)[_BROADCAST[a]] for a in range(3)] for row in range(3)]
    z = terms[2][0] + terms[2][1] + terms[2][2]
    inv = np.float32(1.0) / np.where(z > 1e-9, z, np.float32(np.inf))  # 0 behind the camera
    u = (terms[0][0] + terms[0][1] + terms[0][2]) * inv * np.float32(k.fx) + np.float32(k.cx + 0.5)
    v = (terms[1][0] + terms[1][1] + terms[1][2]) * inv * np.float32(k.fy) + np.float32(k.cy + 0.5)
    inside = (inv > 0) & (u >= 0) & (u < k.width) & (v >= 0) & (v < k.height)
    depth = frame.depth[v[inside].astype(np.intp), u[inside].astype(np.intp)]  # floor(x + 0.5): nearest pixel
    return z, inside, depth


def observe_projective(frame: DepthFrame, lower: ArrayLike, resolution: float, shape: ArrayLike) -> NDArray[np.uint8]:
    """What one frame says about each voxel, by projecting voxel centres and corners into the depth image.

    lower: (3,) world lower corner of voxel (0, 0, 0); shape: (3,) voxel counts.
    Returns (X, Y, Z) uint8: ``VoxelClass.EMPTY``, ``VoxelClass.UNKNOWN`` or 0 (unchanged:
    the centre is behind the camera or projects outside the image).

    A voxel is EMPTY when every sampled ray through it reaches past it, otherwise UNKNOWN:

    - centre: ``c`` at camera depth ``z`` falls in pixel ``(u, v)`` (rounded) of depth ``d``.
      The ray from the camera ``o`` through ``c`` leaves the voxel at ``z_exit = z + h`` with
      ``h = (resolution / 2) * z / max_i |c_i - o_i|``, the voxel's half-chord along that ray in
      depth units (between ``resolution / 2`` and ``sqrt(3) / 2 * resolution`` times the ray's
      cosine to the optical axis): an exact tolerance, not a fixed band. The centre ray passes
      when ``d == 0`` (no return: free space up to the sensor's range, beyond B) or
      ``z_exit <= d + EMPTY_EPS``.
    - corners: each of the 8 corners, at depth ``z_k`` in a pixel of depth ``d_k``, is blocked when
      ``0 < d_k < z_k - EMPTY_EPS`` (a surface in front of it). Corners outside the image are ignored.

    The centre test alone is the Amanatides–Woo rule of ``planner.raycast`` for the one ray
    through the centre; the corner test makes the projective model as conservative as the
    raycast at depth discontinuities, where only part of a voxel is occluded. Without it the
    voxels just behind a silhouette (which often hold the hidden surface) would be carved
    EMPTY, and EMPTY is final (a sphere seen from four views lost 13 % of its surface voxels).
    The two models then differ only on voxels where the samples and the pixel rays see
    different parts of an occlusion edge (about 1 % of the touched voxels at 0.01 m) and at
    the frustum's border.
    """
    lo = checked_array("lower", lower, (3,))
    shp = tuple(int(n) for n in np.asarray(shape).reshape(3))
    out = np.zeros(shp, dtype=np.uint8)
    if out.size == 0:
        return out
    res, eye = float(resolution), frame.T_world_camera.translation
    offs = [lo[a] + (np.arange(shp[a]) + 0.5) * res - eye[a] for a in range(3)]
    z, inside, d = _project(frame, offs)
    a0, a1, a2 = (np.abs(offs[a]).astype(np.float32)[_BROADCAST[a]] for a in range(3))
    m = np.maximum(np.maximum(a0, a1), a2)[inside]  # > 0 for points in front of the camera
    zi = z[inside]
    z_exit = zi + np.float32(0.5 * res) * zi / m
    empty = (d == 0) | (z_exit <= d + np.float32(EMPTY_EPS))
    # corners: a lattice of (X+1, Y+1, Z+1) points shared by neighbouring voxels
    cz, cin, cd = _project(frame, [lo[a] + np.arange(shp[a] + 1) * res - eye[a] for a in range(3)])
    blocked_corner = np.zeros(cz.shape, dtype=bool)
    blocked_corner[cin] = (cd > 0) & (cd < cz[cin] - np.float32(EMPTY_EPS))
    b = blocked_corner  # voxel (i, j, k) has corners (i..i+1, j..j+1, k..k+1): OR pairs along each axis
    b = b[:-1] | b[1:]
    b = b[:, :-1] | b[:, 1:]
    b = b[:, :, :-1] | b[:, :, 1:]
    empty &= ~b[inside]
    out[inside] = np.where(empty, np.uint8(VoxelClass.EMPTY), np.uint8(VoxelClass.UNKNOWN))
    return out


def _index_range(mask: NDArray[np.bool_]) -> tuple[NDArray[np.int64], NDArray[np.int64]] | None:
    """Grid index range [lo, hi) of the True voxels of ``mask`` (X, Y, Z), or None."""
    lo, hi = np.zeros(3, np.int64), np.zeros(3, np.int64)
    for ax in range(3):
        others = tuple(a for a in range(3) if a != ax)
        nz = np.flatnonzero(mask.any(axis=others))
        if nz.size == 0:
            return None
        lo[ax], hi[ax] = nz[0], nz[-1] + 1
    return lo, hi


def _regrid(classes: NDArray[np.uint8], old_lo: NDArray[np.int64] | None, rng: bb.LatticeRange) -> NDArray[np.uint8]:
    """``classes`` moved onto the lattice range ``rng`` (a superset of the old one); new voxels NONE."""
    new_lo, new_hi = rng
    if old_lo is not None and np.array_equal(old_lo, new_lo) and classes.shape == tuple(new_hi - new_lo):
        return classes
    out = np.zeros(tuple(int(n) for n in new_hi - new_lo), dtype=np.uint8)
    if old_lo is not None and classes.size:
        o = old_lo - new_lo
        out[o[0] : o[0] + classes.shape[0], o[1] : o[1] + classes.shape[1], o[2] : o[2] + classes.shape[2]] = classes
    return out


class VoxelMap:
    """Voxel map over B; see the module docstring for the per-frame order.

    config: resolution, gamma, initial_diagonal_factor, max_extent, integration mode.
    ray_stride: for ``integration == "raycast"``, cast a ray through every ``ray_stride``-th pixel.
    """

    def __init__(self, config: VoxelConfig | None = None, *, ray_stride: int = 1) -> None:
        self._config = config if config is not None else VoxelConfig()
        if int(ray_stride) != ray_stride or ray_stride < 1:
            raise ValueError(f"ray_stride: must be an integer >= 1, got {ray_stride!r}")
        self._ray_stride = int(ray_stride)
        self._lo: NDArray[np.int64] | None = None
        self._classes: NDArray[np.uint8] = np.zeros((0, 0, 0), dtype=np.uint8)
        self._frames = 0  # see ``frames``

    # ------------------------------------------------------------------ properties

    @property
    def config(self) -> VoxelConfig:
        return self._config

    @property
    def frames(self) -> int:
        """Frames integrated so far (changes exactly when the map may have)."""
        return self._frames

    @property
    def resolution(self) -> float:
        return self._config.resolution

    @property
    def lower_index(self) -> NDArray[np.int64] | None:
        """(3,) int64 lattice index of grid voxel (0, 0, 0); None before the first frame."""
        return None if self._lo is None else self._lo.copy()

    @property
    def origin(self) -> NDArray[np.float64]:
        """(3,) world position of the lower corner of voxel (0, 0, 0) (zeros before the first frame)."""
        return np.zeros(3) if self._lo is None else (self._lo * self.resolution).astype(np.float64)

    @property
    def shape(self) -> tuple[int, int, int]:
        s = self._classes.shape
        return (int(s[0]), int(s[1]), int(s[2]))

    @property
    def bbox(self) -> BoundingBox | None:
        """B, snapped to the lattice; None before the first frame."""
        if self._lo is None:
            return None
        return bb.range_box((self._lo, self._lo + np.array(self.shape)), self.resolution)

    @property
    def classes(self) -> NDArray[np.uint8]:
        """(X, Y, Z) uint8 ``VoxelClass`` codes, a read-only view."""
        view = self._classes.view()
        view.setflags(write=False)
        return view

    def centers(self, cls: VoxelClass) -> NDArray[np.float64]:
        """(N, 3) float64 world centres of the voxels of class ``cls``."""
        idx = np.argwhere(self._classes == cls)
        if self._lo is None or idx.size == 0:
            return np.zeros((0, 3))
        return (((idx + self._lo) + 0.5) * self.resolution).astype(np.float64)

    def count(self, cls: VoxelClass) -> int:
        return int(np.count_nonzero(self._classes == cls))

    def voxel_of(self, points: ArrayLike) -> NDArray[np.int64]:
        """(N, 3) int64 grid indices of the voxels containing ``points`` (N, 3) (may lie outside the grid)."""
        p = checked_array("points", points, (None, 3))
        lo = np.zeros(3, np.int64) if self._lo is None else self._lo
        return np.floor(p / self.resolution).astype(np.int64) - lo

    def snapshot(self) -> VoxelSnapshot:
        return VoxelSnapshot(
            resolution=self.resolution,
            occupied=self.centers(VoxelClass.OCCUPIED),
            frontier=self.centers(VoxelClass.FRONTIER),
            unknown=self.centers(VoxelClass.UNKNOWN),
            empty=self.centers(VoxelClass.EMPTY),
        )

    def copy(self) -> VoxelMap:
        """A deep copy (to roll back on errors)."""
        return copy.deepcopy(self)

    # ------------------------------------------------------------------ integration

    def _observe(self, frame: DepthFrame, lower: NDArray[np.float64], shape: tuple[int, ...]) -> NDArray[np.uint8]:
        if self._config.integration == "raycast":
            return observe_raycast(frame, lower, self.resolution, shape, self._ray_stride)
        return observe_projective(frame, lower, self.resolution, shape)

    def integrate(self, frame: DepthFrame, points_world: ArrayLike) -> IntegrationStats:
        """Add one frame: ``frame`` (depth, pose, intrinsics) carves EMPTY / UNKNOWN, ``points_world``
        (N, 3) float64 (the frame's preprocessed points) make OCCUPIED. See the module docstring."""
        t0 = time.perf_counter()
        if not isinstance(frame, DepthFrame):
            raise ValueError(f"frame: must be a DepthFrame, got {type(frame).__name__}")
        pts = checked_array("points_world", points_world, (None, 3))
        first = self._lo is None
        if first and pts.shape[0] == 0:
            raise ValueError("empty frame: points_world has no points, cannot initialise the bounding box B")
        cfg, res = self._config, self.resolution
        n_max = bb.max_voxels(cfg.max_extent, res)
        old_rng = None if self._lo is None else (self._lo, self._lo + np.array(self.shape))

        # (1) grow B to cover the new points
        pidx = np.floor(pts / res).astype(np.int64)  # (N, 3) lattice voxel of each point
        pts_rng = bb.index_range(pidx)
        content = bb.range_union(self._occupied_range(), pts_rng)
        assert content is not None
        center = 0.5 * (content[0] + content[1])
        if old_rng is None:
            assert pts_rng is not None
            b0 = bb.range_box(pts_rng, res)
            grown = bb.grow_along_view(b0, frame.T_world_camera.rotation[:, 2], cfg.initial_diagonal_factor)
            rng = bb.cap_range(bb.lattice_range(grown, res), None, center, n_max)
        else:
            want = bb.range_union(old_rng, pts_rng)
            assert want is not None
            rng = bb.cap_range(want, old_rng, center, n_max)
        rng = bb.floor_range(rng, cfg.floor_height if cfg.floor else None, res)
        before = _regrid(self._classes, self._lo, rng)
        lo = rng[0]

        # (2) classify what the frame observed; final voxels never change
        obs = self._observe(frame, (lo * res).astype(np.float64), before.shape)
        mutable = (before != VoxelClass.EMPTY) & (before != VoxelClass.OCCUPIED)
        new = before.copy()
        new[mutable & (obs == VoxelClass.EMPTY)] = VoxelClass.EMPTY
        new[mutable & (obs == VoxelClass.UNKNOWN)] = VoxelClass.UNKNOWN
        X, Y, Z = new.shape
        gx, gy, gz = (pidx[:, a] - lo[a] for a in range(3))
        inside = (gx >= 0) & (gx < X) & (gy >= 0) & (gy < Y) & (gz >= 0) & (gz < Z)
        flat = ((gx * Y + gy) * Z + gz)[inside]
        np.put(new, flat[mutable.reshape(-1)[flat]], np.uint8(VoxelClass.OCCUPIED))

        # (3) frontier
        new = relabel_frontier(new)

        # (4) grow B to cover gamma-spheres around frontier voxels (V_o is inside B by construction)
        f_rng = _index_range(new == VoxelClass.FRONTIER)
        if f_rng is not None:
            f_lo = ((f_rng[0] + lo + 0.5) * res - cfg.gamma).astype(np.float64)
            spheres = BoundingBox(f_lo, ((f_rng[1] + lo - 0.5) * res + cfg.gamma).astype(np.float64))
            cur = (lo, lo + np.array(new.shape))
            want = bb.range_union(cur, bb.lattice_range(spheres, res))
            occ = _index_range(new == VoxelClass.OCCUPIED)
            content = bb.range_union(None if occ is None else (occ[0] + lo, occ[1] + lo), pts_rng) or content
            assert want is not None
            rng2 = bb.cap_range(want, cur, 0.5 * (content[0] + content[1]), n_max)
            rng2 = bb.floor_range(rng2, cfg.floor_height if cfg.floor else None, res)
            new, before = _regrid(new, lo, rng2), _regrid(before, lo, rng2)
            lo = rng2[0]

        new_occ = int(np.count_nonzero((new == VoxelClass.OCCUPIED) & (before != VoxelClass.OCCUPIED)))
        new_empty = int(np.count_nonzero((new == VoxelClass.EMPTY) & (before != VoxelClass.EMPTY)))
        new_unknown = int(
            np.count_nonzero(((new == VoxelClass.UNKNOWN) | (new == VoxelClass.FRONTIER)) & (before == VoxelClass.NONE))
        )
        grew = old_rng is None or not (np.array_equal(old_rng[0], lo) and new.shape == self._classes.shape)
        stats = IntegrationStats(
            n_new_occupied=new_occ,
            n_new_empty=new_empty,
            n_new_unknown=new_unknown,
            n_frontier=int(np.count_nonzero(new == VoxelClass.FRONTIER)),
            n_points_outside=int(np.count_nonzero(~inside)),
            bbox_grew=bool(grew),
            seconds=time.perf_counter() - t0,
        )
        self._classes, self._lo = new, lo.copy()  # commit
        self._frames += 1
        return stats

    def _occupied_range(self) -> bb.LatticeRange | None:
        """Lattice range of the OCCUPIED voxels, or None."""
        if self._lo is None:
            return None
        r = _index_range(self._classes == VoxelClass.OCCUPIED)
        return None if r is None else (r[0] + self._lo, r[1] + self._lo)
