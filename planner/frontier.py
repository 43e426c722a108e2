"""Frontier voxels (paper §III-C, eq. 1): unknown voxels next to both free space and surface.

FRONTIER is a derived label: it is recomputed from UNKNOWN ∪ FRONTIER after every
integration, so a frontier voxel that no longer qualifies returns to UNKNOWN.
The neighbourhood is the 26-neighbourhood (3 x 3 x 3 cube minus the voxel);
voxels outside the grid count as NONE.
"""

from __future__ import annotations

import numpy as np
from numpy.typing import NDArray

from planner.types import VoxelClass


def dilate_bits(bits: NDArray[np.uint8]) -> NDArray[np.uint8]:
    """(X, Y, Z) uint8: bitwise OR of each voxel's 3 x 3 x 3 cube (outside the grid counts as 0).

    The cube is separable, so this is three 1-D passes of shifted ORs; several masks packed as
    bits are dilated at once. Same result as ``scipy.ndimage.binary_dilation`` with a 3 x 3 x 3
    structure per bit, about 50x faster than ``scipy.ndimage.maximum_filter`` on these grids.
    """
    out = bits
    for ax in range(3):
        src, out = out, out.copy()
        up = tuple(slice(1, None) if a == ax else slice(None) for a in range(3))
        down = tuple(slice(None, -1) if a == ax else slice(None) for a in range(3))
        out[up] |= src[down]
        out[down] |= src[up]
    return out


def _check(classes: NDArray[np.uint8]) -> NDArray[np.uint8]:
    c = np.asarray(classes)
    if c.ndim != 3 or c.dtype != np.uint8:
        raise ValueError(f"classes: expected a 3-D uint8 array, got {c.ndim}-D {c.dtype}")
    return c


def frontier_mask(classes: NDArray[np.uint8]) -> NDArray[np.bool_]:
    """(X, Y, Z) bool: UNKNOWN (or FRONTIER) voxels with >= 1 EMPTY and >= 1 OCCUPIED 26-neighbour.

    classes: (X, Y, Z) uint8 ``VoxelClass`` codes.
    """
    c = _check(classes)
    if c.size == 0:
        return np.zeros(c.shape, dtype=bool)
    unknown = (c == VoxelClass.UNKNOWN) | (c == VoxelClass.FRONTIER)
    # The voxel itself is unknown, so "voxel or neighbour" == "some neighbour" for the other classes.
    bits = (c == VoxelClass.EMPTY).view(np.uint8) | ((c == VoxelClass.OCCUPIED).view(np.uint8) << 1)
    return unknown & (dilate_bits(bits) == 3)


def relabel_frontier(classes: NDArray[np.uint8]) -> NDArray[np.uint8]:
    """A new (X, Y, Z) uint8 array with FRONTIER / UNKNOWN recomputed from UNKNOWN ∪ FRONTIER."""
    c = _check(classes)
    out = c.copy()
    out[c == VoxelClass.FRONTIER] = VoxelClass.UNKNOWN
    out[frontier_mask(c)] = VoxelClass.FRONTIER
    return out
