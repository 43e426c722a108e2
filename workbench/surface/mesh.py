"""``SurfaceMesh``: a triangle mesh as a frozen value, in a canonical order so equal surfaces compare equal."""

from __future__ import annotations

from dataclasses import dataclass
from functools import cached_property

import numpy as np
import trimesh
from numpy.typing import ArrayLike, NDArray


class SurfaceError(ValueError):
    """A surface cannot be built or used: no frames, a bad frame or pose, nothing left after the cuts."""


@dataclass(frozen=True, eq=False)
class SurfaceMesh:
    """A triangle mesh in the world frame (z-up, plate top at z = 0).

    vertices: (V, 3) float64, finite. faces: (F, 3) int64, indices into ``vertices``.
    Build one with :meth:`canonical` to get the order that makes equal surfaces equal arrays.
    """

    vertices: NDArray[np.float64]
    faces: NDArray[np.int64]

    def __post_init__(self) -> None:
        v = np.asarray(self.vertices, dtype=np.float64)
        f = np.asarray(self.faces, dtype=np.int64)
        if v.ndim != 2 or v.shape[1] != 3:
            raise SurfaceError(f"vertices: expected shape (V, 3), got {v.shape}")
        if f.ndim != 2 or f.shape[1] != 3:
            f = f.reshape(0, 3) if f.size == 0 else f
            if f.ndim != 2 or f.shape[1] != 3:
                raise SurfaceError(f"faces: expected shape (F, 3), got {f.shape}")
        if not np.all(np.isfinite(v)):
            raise SurfaceError("vertices: non-finite values")
        if len(f) and (f.min() < 0 or f.max() >= len(v)):
            raise SurfaceError("faces: index out of range of vertices")
        v.setflags(write=False)
        f.setflags(write=False)
        object.__setattr__(self, "vertices", v)
        object.__setattr__(self, "faces", f)

    @staticmethod
    def canonical(vertices: ArrayLike, faces: ArrayLike) -> SurfaceMesh:
        """The mesh with unused vertices dropped, vertices sorted (x, then y, then z), each face rotated to start
        at its smallest index (orientation kept) and faces sorted: independent of the order a library emitted
        them in (open3d's hash maps and threads), so a rebuild from the same frames is equal array for array."""
        v = np.asarray(vertices, dtype=np.float64).reshape(-1, 3)
        f = np.asarray(faces, dtype=np.int64).reshape(-1, 3)
        used = np.bincount(f.ravel(), minlength=len(v)) > 0
        v = v[used]
        f = (np.cumsum(used) - 1)[f]
        order = np.lexsort((v[:, 2], v[:, 1], v[:, 0]))
        rank = np.empty_like(order)
        rank[order] = np.arange(len(order))
        v, f = v[order], rank[f]
        shift = np.argmin(f, axis=1)
        rows = np.arange(len(f))[:, None]
        f = f[rows, (shift[:, None] + np.arange(3)[None, :]) % 3]
        n = len(v)
        if n < 2**21:  # three indices packed in one int64 key sort in a tenth of a lexsort's time
            f = f[np.argsort((f[:, 0] * n + f[:, 1]) * n + f[:, 2], kind="stable")]
        else:
            f = f[np.lexsort((f[:, 2], f[:, 1], f[:, 0]))]
        return SurfaceMesh(v, f)

    def __reduce__(self) -> tuple[type[SurfaceMesh], tuple[NDArray[np.float64], NDArray[np.int64]]]:
        """Pickled as its two arrays: not the trimesh (and its caches) :attr:`area` builds, five times the bytes."""
        return (SurfaceMesh, (self.vertices, self.faces))

    @property
    def triangles(self) -> int:
        return len(self.faces)

    @cached_property
    def _trimesh(self) -> trimesh.Trimesh:
        return trimesh.Trimesh(self.vertices.copy(), self.faces.copy(), process=False)

    def to_trimesh(self) -> trimesh.Trimesh:
        """A trimesh copy (unprocessed: the same vertices and faces)."""
        return self._trimesh.copy()

    @property
    def area(self) -> float:
        """Surface area, m^2."""
        return float(self._trimesh.area)

    @property
    def volume(self) -> float:
        """Enclosed volume, m^3 (meaningful when :attr:`watertight`)."""
        return float(self._trimesh.volume)

    @property
    def watertight(self) -> bool:
        """Every edge shared by exactly two faces, consistently wound."""
        return bool(self._trimesh.is_watertight)

    def __eq__(self, other: object) -> bool:
        if not isinstance(other, SurfaceMesh):
            return NotImplemented
        return np.array_equal(self.vertices, other.vertices) and np.array_equal(self.faces, other.faces)

    __hash__ = None  # type: ignore[assignment]
