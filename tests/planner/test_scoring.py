"""Depth-rank weights, weighted projections and F (paper §III-E)."""

from __future__ import annotations

import math

import numpy as np
import pytest

from planner.candidates import propose_candidates
from planner.config import CandidateConfig, PartitionConfig, ScoringConfig
from planner.projection import raster_pixels
from planner.scoring import depth_ranks, rank_weights, score_views
from planner.types import BoundingBox, Candidate, Ellipsoid, Intrinsics, Pose

K = Intrinsics()  # 640 x 480, f = 610


def sphere(center, r: float, kind: str = "occupied") -> Ellipsoid:
    return Ellipsoid(np.asarray(center, float), np.full(3, r), np.eye(3), kind)  # type: ignore[arg-type]


def candidate(pose: Pose, index: int = 0) -> Candidate:
    return Candidate(index=index, T_world_camera=pose, elevation=0.0, azimuth=0.0, parallel=0, sector=0)


def disk_area(r: float, d: float) -> float:
    """Pixels of a sphere of radius r at distance d seen head-on: pi (f r / sqrt(d^2 - r^2))^2."""
    return math.pi * K.fx**2 * r * r / (d * d - r * r)


AT_ORIGIN = candidate(Pose.identity())  # camera at the world origin looking along +z


def test_ranks_are_the_inverse_permutation_not_argsort() -> None:
    z = [0.5, 0.3, 0.4]  # argsort = [1, 2, 0]; the ranks are [2, 0, 1]
    ells = [sphere([0.1 * i - 0.1, 0.0, zi], 0.02) for i, zi in enumerate(z)]
    (s,) = score_views(ells, [AT_ORIGIN], K, ScoringConfig(), np.array([True]))
    assert np.argsort(z).tolist() != [2, 0, 1]
    assert s.ranks.tolist() == [2, 0, 1]
    np.testing.assert_allclose(s.weights, [0.25, 1.0, 0.5])
    np.testing.assert_allclose(s.weighted, s.weights * s.pixels)
    want = [disk_area(0.02, math.hypot(0.1 * i - 0.1, zi)) for i, zi in enumerate(z)]
    np.testing.assert_allclose(s.pixels[1], want[1], rtol=1e-9)  # on the optical axis: exactly the disk
    ref = [raster_pixels(e, AT_ORIGIN.T_world_camera, K) for e in ells]  # off axis: elongated ellipses
    np.testing.assert_allclose(s.pixels, ref, rtol=0.02)


def test_ranks_follow_the_view_not_the_input_order() -> None:
    ells = [sphere([0.0, 0.0, zi], 0.01) for zi in (0.3, 0.4, 0.5)]
    forward = candidate(Pose.identity(), 0)
    from_above = candidate(Pose.look_at([0.0, 0.0, 1.0], [0.0, 0.0, 0.0]), 1)  # looks down -z
    s0, s1 = score_views(ells, [forward, from_above], K, ScoringConfig(rank_base=0.25), np.array([True, False]))
    assert s0.ranks.tolist() == [0, 1, 2] and s1.ranks.tolist() == [2, 1, 0]
    np.testing.assert_allclose(s1.weights, [0.0625, 0.25, 1.0])
    assert s0.eligible and not s1.eligible and s1.index == 1
    assert s1.score != 0.0  # ineligible views are scored all the same


def test_ties_keep_input_order() -> None:
    z = np.array([[0.5, 0.2, 0.5, 0.2]])
    assert depth_ranks(z).tolist() == [[2, 0, 3, 1]]


def test_frontier_in_front_of_occupied_scores_positive_and_swapped_negative() -> None:
    r, near, far = 0.05, 0.4, 0.6
    front_f = [sphere([0.0, 0.0, near], r, "frontier"), sphere([0.0, 0.0, far], r, "occupied")]
    front_o = [sphere([0.0, 0.0, near], r, "occupied"), sphere([0.0, 0.0, far], r, "frontier")]
    cfg = ScoringConfig()
    (a,) = score_views(front_f, [AT_ORIGIN], K, cfg, np.array([True]))
    (b,) = score_views(front_o, [AT_ORIGIN], K, cfg, np.array([True]))
    L_near, L_far = disk_area(r, near), disk_area(r, far)
    assert a.score == pytest.approx(L_near - 0.5 * L_far, rel=1e-9)
    assert a.frontier == pytest.approx(L_near, rel=1e-9) and a.occupied == pytest.approx(0.5 * L_far, rel=1e-9)
    assert b.score == pytest.approx(0.5 * L_far - L_near, rel=1e-9)
    assert a.score > 0 > b.score
    assert a.score == pytest.approx(14468.0, rel=1e-4)  # 610^2 pi 0.0025 (1/0.1575 - 0.5/0.3575)


def test_behind_the_camera_contributes_nothing_and_does_not_shift_ranks() -> None:
    ells = [
        sphere([0.0, 0.0, -0.5], 0.05, "frontier"),  # wholly behind
        sphere([0.0, 0.0, 0.5], 0.05, "frontier"),
        Ellipsoid(np.array([0.05, 0.0, -0.02]), np.array([0.03, 0.03, 0.3]), np.eye(3), "frontier"),  # centre behind
        sphere([0.05, 0.0, 0.7], 0.05, "occupied"),
    ]
    (s,) = score_views(ells, [AT_ORIGIN], K, ScoringConfig(), np.array([True]))
    assert s.ranks.tolist() == [-1, 0, -1, 1]
    np.testing.assert_allclose(s.weights, [0.0, 1.0, 0.0, 0.5])
    assert s.pixels[0] == 0.0
    assert s.pixels[2] > 1000  # straddles z = 0: visible in part, but its centre is behind -> weight 0
    assert s.weighted[0] == 0.0 and s.weighted[2] == 0.0
    assert s.score == pytest.approx(s.pixels[1] - 0.5 * s.pixels[3], rel=1e-12)


def test_rank_weights_values() -> None:
    np.testing.assert_allclose(rank_weights(np.array([[0, 1, 3, -1]]), 0.5), [[1.0, 0.5, 0.125, 0.0]])
    np.testing.assert_allclose(rank_weights(np.array([0, 5, -1]), 1.0), [1.0, 1.0, 0.0])


def scene() -> tuple[list[Ellipsoid], tuple[Candidate, ...]]:
    rng = np.random.default_rng(7)
    ells = []
    for i in range(12):
        q, _ = np.linalg.qr(rng.normal(size=(3, 3)))
        q *= np.sign(np.linalg.det(q))
        c = rng.uniform([-0.08, -0.08, 0.0], [0.08, 0.08, 0.16])
        ells.append(Ellipsoid(c, rng.uniform(0.01, 0.04, 3), q, "frontier" if i % 3 else "occupied"))
    bbox = BoundingBox(np.array([-0.1, -0.1, 0.0]), np.array([0.1, 0.1, 0.2]))
    cands, _, _ = propose_candidates(bbox, CandidateConfig(count=40, parallels=4), PartitionConfig())
    return ells, cands


def test_raster_mode_agrees_with_analytic() -> None:
    ells, cands = scene()
    cands = cands[::8]
    mask = np.ones(len(cands), dtype=bool)
    fast = score_views(ells, cands, K, ScoringConfig(), mask)
    slow = score_views(ells, cands, K, ScoringConfig(area="raster"), mask)
    for f, s in zip(fast, slow, strict=True):
        assert f.ranks.tolist() == s.ranks.tolist()
        np.testing.assert_allclose(f.pixels, s.pixels, rtol=0.03)
        assert f.score == pytest.approx(s.score, rel=0.02, abs=50)
    e, c = ells[0], cands[0]
    assert slow[0].pixels[0] == raster_pixels(e, c.T_world_camera, K)


def test_full_size_scene_scores_every_view() -> None:
    """400 candidates x 108 ellipsoids (its speed: benchmarks/bench_score.py)."""
    ells, _ = scene()
    ells = ells * 9  # 108 ellipsoids
    bbox = BoundingBox(np.array([-0.1, -0.1, 0.0]), np.array([0.1, 0.1, 0.2]))
    cands, _, _ = propose_candidates(bbox, CandidateConfig(), PartitionConfig())
    mask = np.ones(len(cands), dtype=bool)
    scores = score_views(ells, cands, K, ScoringConfig(), mask)
    assert len(scores) == 400 and all(len(s.pixels) == 108 for s in scores)
    # nine copies of each ellipsoid: equal pixel counts, one distinct rank each
    assert all(len(set(s.ranks.tolist())) == len(s.ranks) for s in scores)


def test_empty_inputs() -> None:
    (s,) = score_views([], [AT_ORIGIN], K, ScoringConfig(), np.array([True]))
    assert s.score == 0.0 and s.ranks.shape == (0,) and s.pixels.shape == (0,)
    assert score_views([sphere([0, 0, 1], 0.1)], [], K, ScoringConfig(), np.zeros(0, dtype=bool)) == ()


def test_bad_input_raises() -> None:
    e = [sphere([0, 0, 1], 0.1)]
    with pytest.raises(ValueError, match="eligible"):
        score_views(e, [AT_ORIGIN], K, ScoringConfig(), np.array([True, False]))
    with pytest.raises(ValueError, match="eligible"):
        score_views(e, [AT_ORIGIN], K, ScoringConfig(), np.array([1]))
    with pytest.raises(ValueError, match="ellipsoids\\[0\\]"):
        score_views(["x"], [AT_ORIGIN], K, ScoringConfig(), np.array([True]))  # type: ignore[list-item]
    with pytest.raises(ValueError, match="candidates\\[0\\]"):
        score_views(e, [Pose.identity()], K, ScoringConfig(), np.array([True]))  # type: ignore[list-item]
    with pytest.raises(ValueError, match="config"):
        score_views(e, [AT_ORIGIN], K, None, np.array([True]))  # type: ignore[arg-type]
    with pytest.raises(ValueError, match="z"):
        depth_ranks(np.zeros(3))
