"""Frontier voxels: unknown with an empty and an occupied voxel among their 26 neighbours."""

from __future__ import annotations

import itertools

import numpy as np
import pytest

from planner.frontier import frontier_mask, relabel_frontier
from planner.types import VoxelClass

E, O, U, F, N = VoxelClass.EMPTY, VoxelClass.OCCUPIED, VoxelClass.UNKNOWN, VoxelClass.FRONTIER, VoxelClass.NONE


def _hand_grid() -> np.ndarray:
    """5x5x5: layer x=0 empty, one occupied voxel at (2,2,2), the rest unknown, with a few special cases."""
    c = np.full((5, 5, 5), U, dtype=np.uint8)
    c[0] = E
    c[2, 2, 2] = O
    c[1, 2, 2] = N  # not unknown: never frontier
    c[4, 4, 4] = F  # stale frontier label, no empty neighbour: back to unknown
    return c


def test_frontier_exactly_on_hand_made_grid() -> None:
    mask = frontier_mask(_hand_grid())
    # unknown voxels next to layer 0 (so x == 1) and within one step of (2,2,2) (so y, z in 1..3), minus the NONE one
    expected = np.zeros((5, 5, 5), dtype=bool)
    expected[1, 1:4, 1:4] = True
    expected[1, 2, 2] = False
    np.testing.assert_array_equal(mask, expected)
    assert mask.sum() == 8


def test_relabel_returns_stale_frontier_to_unknown_and_keeps_other_classes() -> None:
    c = _hand_grid()
    out = relabel_frontier(c)
    assert out[4, 4, 4] == U
    assert np.count_nonzero(out == F) == 8
    keep = (c != U) & (c != F)
    np.testing.assert_array_equal(out[keep], c[keep])
    assert c[4, 4, 4] == F  # input untouched


def test_needs_both_an_empty_and_an_occupied_neighbour() -> None:
    c = np.full((3, 3, 3), U, dtype=np.uint8)
    c[0, 0, 0] = E
    assert not frontier_mask(c).any()
    c[2, 2, 2] = O  # diagonal corner neighbours of the centre
    mask = frontier_mask(c)
    assert mask[1, 1, 1]
    assert mask.sum() == 1  # only the centre touches both corners
    # grid border counts as NONE, not as empty
    assert not frontier_mask(np.full((2, 2, 2), U, dtype=np.uint8)).any()


@pytest.mark.parametrize("seed", range(3))
def test_matches_brute_force_26_neighbourhood(seed: int) -> None:
    rng = np.random.default_rng(seed)
    c = rng.choice(np.array([N, E, O, U, F], dtype=np.uint8), size=(7, 6, 5), p=[0.1, 0.15, 0.1, 0.55, 0.1])
    expected = np.zeros(c.shape, dtype=bool)
    for i, j, k in itertools.product(*map(range, c.shape)):
        if c[i, j, k] not in (U, F):
            continue
        nb = c[max(i - 1, 0) : i + 2, max(j - 1, 0) : j + 2, max(k - 1, 0) : k + 2]
        expected[i, j, k] = bool(np.any(nb == E) and np.any(nb == O))
    np.testing.assert_array_equal(frontier_mask(c), expected)


def test_rejects_bad_arrays() -> None:
    with pytest.raises(ValueError, match="classes"):
        frontier_mask(np.zeros((3, 3), dtype=np.uint8))
    with pytest.raises(ValueError, match="classes"):
        frontier_mask(np.zeros((3, 3, 3), dtype=np.int64))  # type: ignore[arg-type]
