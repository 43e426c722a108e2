"""The visible-frontier score V of projection-zbuffer (planner.visibility) on hand-made scenes."""

from __future__ import annotations

import re

import numpy as np
import pytest

from planner.config import PlannerConfig, ZBufferConfig
from planner.projection import ray_hits
from planner.scoring import score_views
from planner.types import Candidate, Ellipsoid, Intrinsics, Pose
from planner.visibility import score_visible_frontier, zbuffer_image

RES = 0.01
SMALL = Intrinsics(width=48, height=36, fx=40.0, fy=40.0, cx=23.5, cy=17.5)
"""A camera whose pixels are the raster's: with a 48 x 36 raster, V counts camera pixels."""
CFG = ZBufferConfig(width=48, height=36, measure="pixels")


def sphere(center, r: float, kind: str = "occupied") -> Ellipsoid:
    return Ellipsoid(np.asarray(center, float), np.full(3, r), np.eye(3), kind)  # type: ignore[arg-type]


def candidate(pose: Pose, index: int = 0) -> Candidate:
    return Candidate(index=index, T_world_camera=pose, elevation=0.0, azimuth=0.0, parallel=0, sector=0)


AT_ORIGIN = candidate(Pose.identity())  # looks along +z
ONE = np.array([True])


def hits(e: Ellipsoid, pose: Pose = AT_ORIGIN.T_world_camera) -> np.ndarray:
    """(H, W) bool, the exact ray test of planner.projection: the reference for every count here."""
    return ray_hits(e, pose, SMALL)


def score(ells, cands=(AT_ORIGIN,), cfg: ZBufferConfig = CFG, eligible=ONE, **kw):
    return score_visible_frontier(ells, list(cands), SMALL, cfg, eligible, RES, **kw)


def test_frontier_fully_behind_an_occupied_ellipsoid_scores_zero() -> None:
    wall = sphere([0.0, 0.0, 0.5], 0.15)
    hidden = sphere([0.0, 0.0, 0.8], 0.08, "frontier")
    assert not np.any(hits(hidden) & ~hits(wall))  # every ray to it meets the wall first
    (s,) = score([wall, hidden])
    assert s.score == 0.0 and s.frontier == 0.0
    assert s.pixels[1] == 0.0
    assert s.pixels[0] == hits(hidden).sum() > 50  # the wall hides exactly the frontier's pixels
    assert s.occupied == s.weighted[0] == s.pixels[0]


def test_visible_frontier_scores_its_pixels() -> None:
    f = sphere([0.03, -0.02, 0.6], 0.08, "frontier")
    (s,) = score([f])
    assert s.score == hits(f).sum() > 50
    np.testing.assert_array_equal(s.pixels, [hits(f).sum()])
    np.testing.assert_array_equal(s.weights, [1.0])


def test_partly_hidden_frontier_scores_the_pixels_in_front_of_every_occupied_one() -> None:
    f = sphere([0.0, 0.0, 0.8], 0.12, "frontier")
    o1 = sphere([-0.08, 0.0, 0.45], 0.05)  # both entirely nearer than the frontier
    o2 = sphere([0.07, 0.05, 0.5], 0.04)
    want = hits(f) & ~hits(o1) & ~hits(o2)
    (s,) = score([o1, f, o2])
    assert 0 < want.sum() < hits(f).sum()
    assert s.score == want.sum()
    assert s.pixels[1] == want.sum()
    # each occupied ellipsoid is charged the frontier pixels it hides (o1 and o2 do not overlap in the image)
    assert s.pixels[0] == (hits(f) & hits(o1)).sum() and s.pixels[2] == (hits(f) & hits(o2)).sum()


def test_frontier_in_front_of_occupied_is_visible_even_where_they_overlap() -> None:
    f = sphere([0.0, 0.0, 0.4], 0.05, "frontier")
    o = sphere([0.0, 0.0, 0.7], 0.2)
    (s,) = score([o, f])
    assert s.score == hits(f).sum() and s.occupied == 0.0


def test_depth_tolerance_lets_frontier_just_behind_the_occupied_surface_count() -> None:
    o = sphere([0.0, 0.0, 0.5], 0.05)
    f = sphere([0.0, 0.0, 0.57], 0.03, "frontier")  # its front (0.54) is 1 cm behind o's back... but o's front is 0.45
    (strict,) = score([o, f])
    (loose,) = score([o, f], cfg=ZBufferConfig(width=48, height=36, measure="pixels", depth_tolerance_voxels=10.0))
    assert strict.score == 0.0
    assert loose.score == hits(f).sum()  # 10 cm of tolerance: every pixel of f


def test_invariant_to_an_occupied_ellipsoid_behind_everything() -> None:
    scene = [sphere([0.0, 0.0, 0.5], 0.06), sphere([0.05, 0.02, 0.7], 0.08, "frontier")]
    poses = [candidate(Pose.identity(), 0), candidate(Pose.look_at([0.3, 0.0, 0.0], [0.0, 0.0, 0.6]), 1)]
    before = score(scene, poses, eligible=np.array([True, False]))
    backdrop = sphere([0.0, 0.0, 3.0], 1.0)  # behind everything from both views, covers the whole image
    after = score([*scene, backdrop], poses, eligible=np.array([True, False]))
    for b, a in zip(before, after, strict=True):
        assert a.score == b.score > 0
        np.testing.assert_array_equal(a.pixels[:2], b.pixels)
        assert a.pixels[2] == 0.0
    assert not after[1].eligible and after[1].index == 1


def test_occupied_surface_elsewhere_does_not_lower_the_score_unlike_the_paper() -> None:
    f = sphere([0.0, 0.0, 0.6], 0.05, "frontier")
    beside = sphere([0.25, 0.0, 0.7], 0.1)  # in view, hides nothing
    assert np.any(hits(beside)) and not np.any(hits(beside) & hits(f))
    (alone,) = score([f])
    (crowded,) = score([f, beside])
    assert crowded.score == alone.score
    from planner.config import ScoringConfig

    (paper_alone,) = score_views([f], [AT_ORIGIN], SMALL, ScoringConfig(), ONE)
    (paper_crowded,) = score_views([f, beside], [AT_ORIGIN], SMALL, ScoringConfig(), ONE)
    assert paper_crowded.score < paper_alone.score  # F = frontier - occupied drops


def test_frontier_ellipsoid_around_the_camera_counts_nothing() -> None:
    around = sphere([0.0, 0.0, 0.0], 0.1, "frontier")
    f = sphere([0.0, 0.0, 0.6], 0.05, "frontier")
    (s,) = score([around, f])
    assert s.pixels[0] == 0.0 and s.score == hits(f).sum()


def test_occupied_ellipsoid_around_the_camera_hides_everything() -> None:
    (s,) = score([sphere([0.0, 0.0, 0.0], 0.1), sphere([0.0, 0.0, 0.6], 0.05, "frontier")])
    assert s.score == 0.0


def test_weights_and_hidden_weight() -> None:
    o = sphere([-0.06, 0.0, 0.45], 0.05)
    f = sphere([0.0, 0.0, 0.8], 0.12, "frontier")
    shown, hidden = (hits(f) & ~hits(o)).sum(), (hits(f) & hits(o)).sum()
    (s,) = score([o, f], frontier_weights=[7.0, 0.5])  # occupied entries are not used
    assert s.score == pytest.approx(0.5 * shown)
    assert s.occupied == pytest.approx(0.5 * hidden) and s.weights[0] == pytest.approx(0.5)
    (h,) = score([o, f], cfg=ZBufferConfig(width=48, height=36, measure="pixels", hidden_weight=0.25))
    assert h.score == pytest.approx(shown + 0.25 * hidden) and h.frontier == shown


def test_coarse_raster_counts_blocks_of_pixels() -> None:
    f = sphere([0.0, 0.0, 0.6], 0.2, "frontier")
    (fine,) = score([f])
    (coarse,) = score([f], cfg=ZBufferConfig(width=24, height=18, measure="pixels"))
    assert fine.score > 500
    assert coarse.score == pytest.approx(fine.score / 4, rel=0.05)  # 2 x 2 camera pixels per raster pixel


def test_zbuffer_image_shows_what_the_score_counts() -> None:
    o = sphere([-0.06, 0.0, 0.45], 0.05)
    f = sphere([0.0, 0.0, 0.8], 0.12, "frontier")
    img = zbuffer_image([o, f], Pose.identity(), SMALL, CFG, RES)
    (s,) = score([o, f])
    assert img.visible.shape == (36, 48)
    assert img.visible.sum() == s.score
    np.testing.assert_array_equal(img.visible, hits(f) & ~hits(o))
    np.testing.assert_array_equal(img.frontier_owner == 1, hits(f))
    np.testing.assert_array_equal(img.occupied_owner == 0, hits(o))
    assert np.all(np.isinf(img.occupied_depth[~hits(o)]))
    assert img.occupied_depth[18, 19] == pytest.approx(0.4, abs=0.01)  # near o's front


def test_all_candidates_are_scored_and_keep_their_order() -> None:
    f = sphere([0.0, 0.0, 0.6], 0.05, "frontier")
    cands = [candidate(Pose.identity(), 0), candidate(Pose.look_at([0, 0, 1.2], [0, 0, 2.0]), 1)]  # 2nd looks away
    a, b = score([f], cands, eligible=np.array([False, True]))
    assert a.score > 0 and not a.eligible and b.score == 0.0 and b.eligible and b.index == 1


def test_no_ellipsoids_and_no_candidates() -> None:
    (s,) = score([])
    assert s.score == 0.0 and len(s.pixels) == 0
    assert score([sphere([0, 0, 1], 0.1)], cands=(), eligible=np.zeros(0, dtype=bool)) == ()


@pytest.mark.parametrize(
    ("kwargs", "field"),
    [
        ({"eligible": np.array([1])}, "eligible"),
        ({"eligible": np.array([True, False])}, "eligible"),
        ({"cfg": PlannerConfig().scoring}, "config"),
        ({"frontier_weights": [1.0]}, "frontier_weights"),
        ({"frontier_weights": [1.0, -1.0]}, "frontier_weights"),
        ({"frontier_weights": [1.0, np.nan]}, "frontier_weights"),
    ],
)
def test_bad_input_names_the_field(kwargs: dict, field: str) -> None:
    ells = [sphere([0, 0, 0.5], 0.05), sphere([0, 0, 0.7], 0.05, "frontier")]
    with pytest.raises(ValueError, match="^" + re.escape(field) + ":"):
        score(ells, **kwargs)


def test_bad_resolution_and_objects_name_the_field() -> None:
    with pytest.raises(ValueError, match=r"^resolution:"):
        score_visible_frontier([], [AT_ORIGIN], SMALL, CFG, ONE, 0.0)
    with pytest.raises(ValueError, match=re.escape("candidates[0]:")):
        score_visible_frontier([], [Pose.identity()], SMALL, CFG, ONE, RES)  # type: ignore[list-item]
    with pytest.raises(ValueError, match=re.escape("ellipsoids[0]:")):
        score_visible_frontier(["x"], [AT_ORIGIN], SMALL, CFG, ONE, RES)  # type: ignore[list-item]
    with pytest.raises(ValueError, match=r"^config:"):
        zbuffer_image([], Pose.identity(), SMALL, PlannerConfig(), RES)  # type: ignore[arg-type]


@pytest.mark.parametrize(
    ("section", "field"),
    [
        ({"width": 0}, "zbuffer.width"),
        ({"height": 4096}, "zbuffer.height"),
        ({"width": 2.5}, "zbuffer.width"),
        ({"depth_tolerance_voxels": -1.0}, "zbuffer.depth_tolerance_voxels"),
        ({"hidden_weight": 1.5}, "zbuffer.hidden_weight"),
        ({"frontier_decay": 0.0}, "zbuffer.frontier_decay"),
        ({"measure": "area"}, "zbuffer.measure"),
    ],
)
def test_config_refuses_bad_values(section: dict, field: str) -> None:
    with pytest.raises(ValueError, match=re.escape(field)):
        PlannerConfig().replace(zbuffer=section)


def test_voxel_measure_is_the_voxel_count_times_the_visible_fraction() -> None:
    o = sphere([-0.06, 0.0, 0.45], 0.05)
    f = Ellipsoid(np.array([0.0, 0.0, 0.8]), np.full(3, 0.12), np.eye(3), "frontier", n_points=40)
    shown, covered = (hits(f) & ~hits(o)).sum(), hits(f).sum()
    (s,) = score([o, f], cfg=ZBufferConfig(width=48, height=36, measure="voxels"))
    assert 0 < shown < covered
    assert s.score == pytest.approx(40.0 * shown / covered)
    assert s.occupied == pytest.approx(40.0 * (covered - shown) / covered)  # what o hides, in voxels
    (alone,) = score([f], cfg=ZBufferConfig(width=48, height=36, measure="voxels"))
    assert alone.score == pytest.approx(40.0)
