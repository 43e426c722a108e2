"""Growth of the bounding box B: view-direction sweep, sphere cover, lattice snapping, the max_extent cap."""

from __future__ import annotations

import math

import numpy as np
import pytest

from planner import bbox as bb
from planner.types import BoundingBox


def test_unit_cube_swept_along_x_has_closed_form_distance() -> None:
    # (1 + s)^2 + 1 + 1 = (2 sqrt 3)^2  ->  s = sqrt(10) - 1
    s = bb.view_growth_distance([1.0, 1.0, 1.0], [1.0, 0.0, 0.0], 2.0)
    assert s == pytest.approx(math.sqrt(10.0) - 1.0, rel=1e-12)


@pytest.mark.parametrize("seed", range(5))
@pytest.mark.parametrize("factor", [1.0, 1.5, 2.0, 3.0])
def test_diagonal_scales_exactly_and_box_grows_only_away_from_camera(seed: int, factor: float) -> None:
    rng = np.random.default_rng(seed)
    lower = rng.uniform(-0.2, 0.2, 3)
    box = BoundingBox(lower, lower + rng.uniform(0.01, 0.3, 3))
    d = rng.normal(size=3)
    grown = bb.grow_along_view(box, d, factor)
    if factor == 1.0:
        np.testing.assert_array_equal(grown.lower, box.lower)
        np.testing.assert_array_equal(grown.upper, box.upper)
        return
    assert grown.diagonal == pytest.approx(factor * box.diagonal, rel=1e-12)
    # faces move only on the far side: upper where d_i > 0, lower where d_i < 0
    for i in range(3):
        if d[i] > 0:
            assert grown.lower[i] == box.lower[i] and grown.upper[i] > box.upper[i]
        else:
            assert grown.upper[i] == box.upper[i] and grown.lower[i] < box.lower[i]
    # the growth is a sweep by s * d_unit: the displacement of the moved faces is parallel to d
    s = bb.view_growth_distance(box.extent, d, factor)
    moved = (grown.upper - box.upper) + (grown.lower - box.lower)
    np.testing.assert_allclose(moved, s * d / np.linalg.norm(d), atol=1e-15)


def test_distance_matches_bisection() -> None:
    e, d, f = np.array([0.12, 0.05, 0.2]), np.array([0.3, -0.8, -0.5]), 2.0
    du = np.abs(d) / np.linalg.norm(d)
    lo, hi = 0.0, 10.0
    for _ in range(200):
        mid = 0.5 * (lo + hi)
        lo, hi = (mid, hi) if np.linalg.norm(e + mid * du) < f * np.linalg.norm(e) else (lo, mid)
    assert bb.view_growth_distance(e, d, f) == pytest.approx(lo, rel=1e-12)


def test_degenerate_box_and_bad_input() -> None:
    assert bb.view_growth_distance([0.0, 0.0, 0.0], [0.0, 0.0, 1.0], 2.0) == 0.0
    with pytest.raises(ValueError, match="direction"):
        bb.view_growth_distance([1.0, 1.0, 1.0], [0.0, 0.0, 0.0], 2.0)
    with pytest.raises(ValueError, match="factor"):
        bb.view_growth_distance([1.0, 1.0, 1.0], [0.0, 0.0, 1.0], 0.5)


def test_union() -> None:
    box = BoundingBox(np.array([-0.02, -0.22, -0.02]), np.array([0.12, 0.02, 0.07]))
    u = bb.union(box, BoundingBox(np.array([0.0, 0.0, 0.0]), np.array([0.5, 0.0, 0.0])))
    assert u is not None
    np.testing.assert_allclose(u.upper, [0.5, 0.02, 0.07])
    assert bb.union(None, box) is box


def test_lattice_snapping_is_outward_and_tolerates_float_noise() -> None:
    lo, hi = bb.lattice_range(BoundingBox(np.array([0.1, -0.013, 0.0]), np.array([0.3, 0.021, 0.0])), 0.01)
    # 0.1 / 0.01 = 10.000000000000002 and 0.3 / 0.01 = 29.999999999999996 stay on their planes
    np.testing.assert_array_equal(lo, [10, -2, 0])
    np.testing.assert_array_equal(hi, [30, 3, 1])  # a flat box still gets one voxel
    assert bb.max_voxels(1.0, 0.01) == 100
    assert bb.max_voxels(0.105, 0.01) == 10


def test_cap_keeps_window_centred_on_content_and_containing_current_box() -> None:
    want = (np.array([-50, 0, 0]), np.array([50, 10, 200]))
    # x: centred on content centre 5 -> [-5, 15); y fits; z: centre 195 would end past 200 -> shifted to [180, 200)
    lo, hi = bb.cap_range(want, None, [5.0, 5.0, 195.0], 20)
    np.testing.assert_array_equal(lo, [-5, 0, 180])
    np.testing.assert_array_equal(hi, [15, 10, 200])
    # the current box must stay inside: x [8, 20) shifts the window to [0, 20); z [150, 165) pulls it to [150, 170)
    keep = (np.array([8, 0, 150]), np.array([20, 10, 165]))
    lo, hi = bb.cap_range(want, keep, [5.0, 5.0, 195.0], 20)
    np.testing.assert_array_equal(lo, [0, 0, 150])
    np.testing.assert_array_equal(hi, [20, 10, 170])
