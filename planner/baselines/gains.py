"""Information-gain formulas of the ray-casting baselines: pure functions on voxel sequences.

A *voxel sequence* is what one ray traverses, in order from the camera: an array
``classes (..., S) uint8`` of ``VoxelClass`` codes, the last axis along the ray,
leading axes batching rays. Shorter rays are padded at the end with ``PAD``
(255). A padding voxel has occupancy probability 0, entropy 0 and is neither
unobserved nor occupied, so padding never changes a gain. Every gain function
returns ``(...,) float64``: one value per ray. The gain of a view is the sum
over its rays (``planner.baselines.evaluators``). The ``*Accumulator`` classes
compute the same gains step by step inside the traversal (no (R, S) array).

Voxel classes -> occupancy probability ``P_o`` (our map stores classes,
the formulas need probabilities):

=========================  =====  ============
class                      P_o    H(P_o), bits
=========================  =====  ============
EMPTY                      0.12   0.529
OCCUPIED                   0.97   0.194
UNKNOWN, FRONTIER, NONE    0.5    1
=========================  =====  ============

FRONTIER is a subset of UNKNOWN (paper §III-C) and NONE is space of B that no
ray has seen yet, so all three are *unobserved*. ``H`` is the binary entropy in
bits. Visibility is ``P_v(x_i) = prod_{j<i} (1 - P_o(x_j))``: the probability
that nothing in front of ``x_i`` blocks the ray (Isler et al.). Public
implementations (``uzh-rpg/rpg_ig_active_reconstruction``, ``psc0628/NBV-Simulation``)
update it with ``p_vis *= p_occ``, a known bug; we use ``1 - P_o``.

Isler et al. (S. Isler, R. Sabzevari, J. Delmerico, D. Scaramuzza, "An Information
Gain Formulation for Active Volumetric 3D Reconstruction", ICRA 2016), per ray:

- Occlusion aware (OA): ``sum_i P_v(x_i) H(x_i)`` over every voxel of the ray
  (EMPTY and OCCUPIED voxels keep some entropy, so they count too).
- Unobserved voxel (UV): ``sum_i P_v(x_i) 1[x_i unobserved]``.
- Rear side entropy (RSE): ``sum_i P_v(x_i) H(x_i) 1[x_i rear side]``. A rear-side
  voxel is an unobserved voxel in the unbroken run of unobserved voxels that the
  ray crosses *just before* it reaches an occupied voxel: the ray comes through
  unobserved space and meets an already-seen surface from its back, so these
  voxels lie directly behind that surface as the earlier views saw it. This is
  the reference implementation's rule (the run is reset by every observed voxel
  and only counts when the ray ends on an occupied voxel). Choices: we do not
  add the occupied voxel's own entropy (the reference does; the indicator is
  for unobserved voxels), and we do not continue past the hit: voxels behind
  the hit are occluded by it from this camera (P_v there is 0.03 of that at the
  hit anyway), and our rays end at the first occupied voxel.

APORA (J. Daudelin, M. Campbell, "An Adaptable, Probabilistic, Next-Best View
Algorithm for Reconstruction of Unknown 3-D Objects", RA-L 2017, as implemented
in Pan's ``NBV-Simulation``): an unobserved voxel ``x`` is on the object with
probability ``p_obj(x) = prod_{k=1..6} exp(-alpha^2 |x - e_k|^2)`` over its 6
nearest frontier voxel centres ``e_k`` (a KD-tree), ``alpha = 0.1 / resolution``.
Units: ``|x - e|`` in metres and ``alpha`` in 1/m (as in the reference, which
queries metric coordinates), so ``alpha |x - e| = 0.1 d`` with ``d`` the distance
in voxel edges: dimensionless and the same at every resolution (one voxel away
from all six: 0.94; five voxels: 0.22; ten: 0.0025). ``p_obj = 0`` for observed
voxels, and everywhere when the map has no frontier voxel; with fewer than 6
frontier voxels all of them are used. The ray gain is
``sum_{i unobserved} p_obj(x_i) prod_{j<i} (1 - p_obj(x_j)) H(x_i)``.
"""

from __future__ import annotations

import numpy as np
from numpy.typing import ArrayLike, NDArray
from scipy.spatial import KDTree

from planner.types import VoxelClass

PAD = 255
"""Class code that pads voxel sequences of different lengths."""

P_EMPTY = 0.12
P_OCCUPIED = 0.97
P_UNOBSERVED = 0.5
APORA_NEIGHBOURS = 6
"""k, the nearest frontier voxels that define ``p_obj``."""
APORA_ALPHA_VOXELS = 0.1
"""alpha * resolution: alpha = 0.1 / resolution (1/m)."""


def binary_entropy(p: ArrayLike) -> NDArray[np.float64]:
    """Binary entropy in bits of probabilities ``p`` (any shape); 0 at p = 0 and p = 1."""
    q = np.asarray(p, dtype=np.float64)
    if np.any((q < 0) | (q > 1) | np.isnan(q)):
        raise ValueError("p: probabilities must lie in [0, 1]")
    with np.errstate(divide="ignore", invalid="ignore"):
        h = -(q * np.log2(q) + (1 - q) * np.log2(1 - q))
    return np.where((q == 0) | (q == 1), 0.0, h)


def _lookup(values: dict[int, float | bool], pad: float | bool, dtype: type) -> NDArray:
    lut = np.full(256, np.nan if dtype is np.float64 else pad, dtype=dtype)
    for code, value in values.items():
        lut[code] = value
    lut[PAD] = pad
    lut.setflags(write=False)
    return lut


_UNOBSERVED_CODES = (VoxelClass.NONE, VoxelClass.UNKNOWN, VoxelClass.FRONTIER)
P_OCC_LUT = _lookup(
    {
        VoxelClass.NONE: P_UNOBSERVED,
        VoxelClass.EMPTY: P_EMPTY,
        VoxelClass.OCCUPIED: P_OCCUPIED,
        VoxelClass.UNKNOWN: P_UNOBSERVED,
        VoxelClass.FRONTIER: P_UNOBSERVED,
    },
    0.0,
    np.float64,
)
"""(256,) float64: P_o by class code; PAD -> 0; other codes NaN (invalid)."""
ENTROPY_LUT = np.where(np.isnan(P_OCC_LUT), np.nan, binary_entropy(np.nan_to_num(P_OCC_LUT)))
"""(256,) float64: H(P_o) in bits by class code; PAD -> 0."""
ENTROPY_LUT.setflags(write=False)
UNOBSERVED_LUT = _lookup({int(c): True for c in _UNOBSERVED_CODES}, False, np.bool_)
"""(256,) bool: NONE, UNKNOWN, FRONTIER."""
OCCUPIED_LUT = _lookup({VoxelClass.OCCUPIED: True}, False, np.bool_)
"""(256,) bool: OCCUPIED."""


def _classes(classes: ArrayLike) -> NDArray[np.uint8]:
    c = np.asarray(classes)
    if c.ndim < 1 or not (np.issubdtype(c.dtype, np.integer) or c.dtype == np.bool_):
        raise ValueError(f"classes: expected an integer array (..., S) of VoxelClass codes, got {c.dtype} {c.shape}")
    if c.dtype != np.uint8:
        if c.size and (c.min() < 0 or c.max() > 255):
            raise ValueError("classes: codes must be VoxelClass values or PAD (255)")
        c = c.astype(np.uint8)
    if c.size and np.isnan(P_OCC_LUT[c]).any():
        raise ValueError("classes: codes must be VoxelClass values (0..4) or PAD (255)")
    return c


def occupancy_probability(classes: ArrayLike) -> NDArray[np.float64]:
    """(..., S) float64 ``P_o`` of each voxel of ``classes (..., S)`` (PAD -> 0)."""
    return P_OCC_LUT[_classes(classes)]


def visibility(p_occ: ArrayLike) -> NDArray[np.float64]:
    """(..., S) float64 ``P_v(x_i) = prod_{j<i} (1 - p_occ_j)`` along the last axis (1 for the first voxel)."""
    p = np.asarray(p_occ, dtype=np.float64)
    if p.ndim < 1:
        raise ValueError("p_occ: expected an array (..., S)")
    vis = np.ones_like(p)
    if p.shape[-1] > 1:
        np.cumprod(1.0 - p[..., :-1], axis=-1, out=vis[..., 1:])
    return vis


def occlusion_aware_gain(classes: ArrayLike) -> NDArray[np.float64]:
    """(...,) Isler OA gain ``sum_i P_v(x_i) H(x_i)`` of voxel sequences ``classes (..., S)``."""
    c = _classes(classes)
    return np.sum(visibility(P_OCC_LUT[c]) * ENTROPY_LUT[c], axis=-1)


def unobserved_voxel_gain(classes: ArrayLike) -> NDArray[np.float64]:
    """(...,) Isler UV gain ``sum_i P_v(x_i) 1[x_i unobserved]`` of ``classes (..., S)``."""
    c = _classes(classes)
    return np.sum(visibility(P_OCC_LUT[c]) * UNOBSERVED_LUT[c], axis=-1)


def rear_side_mask(classes: ArrayLike) -> NDArray[np.bool_]:
    """(..., S) bool: unobserved voxels whose next observed voxel along the ray is OCCUPIED.

    That is the unbroken run of unobserved voxels just before each occupied voxel
    (see the module docstring). PAD and the end of the sequence count as observed, not occupied.
    """
    c = _classes(classes)
    unobserved = UNOBSERVED_LUT[c]
    n = c.shape[-1]
    # index of the first observed voxel at or after i (n when there is none)
    first_observed = np.where(unobserved, n, np.arange(n))
    first_observed = np.flip(np.minimum.accumulate(np.flip(first_observed, -1), axis=-1), -1)
    occupied = np.concatenate([OCCUPIED_LUT[c], np.zeros((*c.shape[:-1], 1), dtype=bool)], axis=-1)
    return unobserved & np.take_along_axis(occupied, first_observed, axis=-1)


def rear_side_entropy_gain(classes: ArrayLike) -> NDArray[np.float64]:
    """(...,) Isler RSE gain ``sum_i P_v(x_i) H(x_i) 1[x_i rear side]`` of ``classes (..., S)``."""
    c = _classes(classes)
    return np.sum(visibility(P_OCC_LUT[c]) * ENTROPY_LUT[c] * rear_side_mask(c), axis=-1)


def apora_gain(classes: ArrayLike, p_obj: ArrayLike) -> NDArray[np.float64]:
    """(...,) APORA gain ``sum_{i unobserved} p_obj_i prod_{j<i} (1 - p_obj_j) H(x_i)``.

    classes: (..., S) class codes; p_obj: (..., S) float64 object probability of each
    voxel (ignored, i.e. taken as 0, for observed voxels and PAD).
    """
    c = _classes(classes)
    p = np.asarray(p_obj, dtype=np.float64)
    if p.shape != c.shape:
        raise ValueError(f"p_obj: expected shape {c.shape} like classes, got {p.shape}")
    if np.any((p < 0) | (p > 1) | np.isnan(p)):
        raise ValueError("p_obj: probabilities must lie in [0, 1]")
    p = np.where(UNOBSERVED_LUT[c], p, 0.0)
    return np.sum(p * visibility(p) * ENTROPY_LUT[c], axis=-1)


class RayGainAccumulator:
    """Streaming form of a ray gain: the traversal ``add``s each step's voxels, ray by ray in order.

    The evaluators use it inside the traversal so that no (R, S) sequence array is built;
    the closed-form functions above are the definitions (a test checks both agree).
    gain: (R,) float64, the gain of each ray so far.
    """

    def __init__(self, n_rays: int) -> None:
        self.gain = np.zeros(n_rays)
        self._vis = np.ones(n_rays)

    def add(
        self, rows: NDArray[np.int64], classes: NDArray[np.uint8], p_obj: NDArray[np.float64] | None = None
    ) -> None:
        """Rays ``rows`` (A,) (distinct) cross their next voxel: ``classes`` (A,) uint8, ``p_obj`` (A,) or None."""
        raise NotImplementedError


_PASS_LUT = 1.0 - P_OCC_LUT  # 1 - P_o: the factor a voxel leaves on the visibility of the voxels behind it


class OcclusionAwareAccumulator(RayGainAccumulator):
    """Streaming ``occlusion_aware_gain``."""

    def add(
        self, rows: NDArray[np.int64], classes: NDArray[np.uint8], p_obj: NDArray[np.float64] | None = None
    ) -> None:
        vis = self._vis[rows]
        self.gain[rows] += vis * ENTROPY_LUT[classes]
        self._vis[rows] = vis * _PASS_LUT[classes]


class UnobservedVoxelAccumulator(RayGainAccumulator):
    """Streaming ``unobserved_voxel_gain``."""

    def add(
        self, rows: NDArray[np.int64], classes: NDArray[np.uint8], p_obj: NDArray[np.float64] | None = None
    ) -> None:
        vis = self._vis[rows]
        self.gain[rows] += vis * UNOBSERVED_LUT[classes]
        self._vis[rows] = vis * _PASS_LUT[classes]


class RearSideEntropyAccumulator(RayGainAccumulator):
    """Streaming ``rear_side_entropy_gain``: the run of unobserved voxels is added when it meets OCCUPIED."""

    def __init__(self, n_rays: int) -> None:
        super().__init__(n_rays)
        self._run = np.zeros(n_rays)

    def add(
        self, rows: NDArray[np.int64], classes: NDArray[np.uint8], p_obj: NDArray[np.float64] | None = None
    ) -> None:
        vis, run = self._vis[rows], self._run[rows]
        hit = OCCUPIED_LUT[classes]
        if hit.any():
            self.gain[rows[hit]] += run[hit]
        unobserved = UNOBSERVED_LUT[classes]
        self._run[rows] = np.where(unobserved, run + vis * ENTROPY_LUT[classes], 0.0)
        self._vis[rows] = vis * _PASS_LUT[classes]


class AporaAccumulator(RayGainAccumulator):
    """Streaming ``apora_gain``; needs ``p_obj``."""

    def add(
        self, rows: NDArray[np.int64], classes: NDArray[np.uint8], p_obj: NDArray[np.float64] | None = None
    ) -> None:
        if p_obj is None:
            raise ValueError("p_obj: APORA needs the object probability of each voxel")
        p = np.where(UNOBSERVED_LUT[classes], p_obj, 0.0)
        vis = self._vis[rows]
        self.gain[rows] += p * vis * ENTROPY_LUT[classes]
        self._vis[rows] = vis * (1.0 - p)


def object_probability(
    points: ArrayLike, frontier: ArrayLike, resolution: float, k: int = APORA_NEIGHBOURS
) -> NDArray[np.float64]:
    """(N,) float64 APORA ``p_obj = prod_k exp(-alpha^2 |x - e_k|^2)`` of ``points (N, 3)`` (metres).

    frontier: (M, 3) frontier voxel centres (metres); the ``min(k, M)`` nearest are used;
    ``alpha = 0.1 / resolution`` (1/m). All zeros when ``M == 0``.
    """
    x = np.asarray(points, dtype=np.float64).reshape(-1, 3)
    e = np.asarray(frontier, dtype=np.float64).reshape(-1, 3)
    if not (np.isfinite(resolution) and resolution > 0):
        raise ValueError(f"resolution: must be > 0, got {resolution!r}")
    if not isinstance(k, int) or k < 1:
        raise ValueError(f"k: must be an integer >= 1, got {k!r}")
    if len(e) == 0 or len(x) == 0:
        return np.zeros(len(x))
    kk = min(k, len(e))
    dist, _ = KDTree(e).query(x, k=kk)
    dist = np.asarray(dist, dtype=np.float64).reshape(len(x), kk)
    alpha = APORA_ALPHA_VOXELS / resolution
    return np.exp(-(alpha**2) * np.sum(dist**2, axis=1))


def object_probability_grid(
    classes: NDArray[np.uint8], origin: ArrayLike, resolution: float, k: int = APORA_NEIGHBOURS
) -> NDArray[np.float64]:
    """(X, Y, Z) float64 ``p_obj`` of every unobserved voxel of ``classes (X, Y, Z)``, 0 elsewhere.

    origin: (3,) world position of the lower corner of voxel (0, 0, 0); voxel centres
    are ``origin + (index + 0.5) * resolution``. Frontier voxels are the FRONTIER class.
    """
    c = np.asarray(classes)
    if c.ndim != 3 or c.dtype != np.uint8:
        raise ValueError(f"classes: expected a 3-D uint8 array, got {c.ndim}-D {c.dtype}")
    o = np.asarray(origin, dtype=np.float64)
    out = np.zeros(c.shape)
    unobserved = UNOBSERVED_LUT[c]
    frontier = np.argwhere(c == VoxelClass.FRONTIER)
    if len(frontier) == 0 or not unobserved.any():
        return out
    unobserved_centres = o + (np.argwhere(unobserved) + 0.5) * resolution
    frontier_centres = o + (frontier + 0.5) * resolution
    out[unobserved] = object_probability(unobserved_centres, frontier_centres, resolution, k)
    return out
