"""Ellipsoids rasterised with their per-pixel depth (planner.zbuffer), against the exact ray test of planner.projection."""

from __future__ import annotations

import re

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from planner.projection import ray_hits
from planner.types import Ellipsoid, Intrinsics, Pose
from planner.zbuffer import raster_rays, rasterize

SMALL = Intrinsics(width=64, height=48, fx=50.0, fy=50.0, cx=31.5, cy=23.5)
"""A camera whose pixels are the raster's (64 x 48 raster of a 64 x 48 image: same pixel centres)."""
AT_ORIGIN = Pose.identity()  # looks along +z


def ellipsoid(center, axes, kind: str = "occupied", rotation=None) -> Ellipsoid:
    R = np.eye(3) if rotation is None else rotation
    return Ellipsoid(np.asarray(center, float), np.asarray(axes, float), R, kind)  # type: ignore[arg-type]


def hit_image(frags, camera: int = 0, ell: int = 0) -> np.ndarray:
    img = np.zeros(frags.width * frags.height, dtype=bool)
    sel = (frags.camera == camera) & (frags.ellipsoid == ell)
    img[frags.pixel[sel]] = True
    return img.reshape(frags.height, frags.width)


def test_raster_rays_go_through_the_centres_of_the_pixel_blocks() -> None:
    k = Intrinsics()  # 640 x 480, f = 610, centre (319.5, 239.5)
    x, y = raster_rays(k, 40, 30)
    assert x.shape == (40,) and y.shape == (30,)
    assert x[0] == pytest.approx((7.5 - 319.5) / 610.0)  # block of camera pixels 0..15: centre 7.5
    assert y[-1] == pytest.approx((471.5 - 239.5) / 610.0)
    x1, _ = raster_rays(k, 640, 480)
    np.testing.assert_allclose(x1, (np.arange(640) - 319.5) / 610.0)  # full size: the camera's own pixels


def test_hits_and_depths_match_the_exact_ray_test() -> None:
    rng = np.random.default_rng(3)
    differing, total = 0, 0
    for trial in range(60):
        R = Rotation.random(rng=np.random.default_rng(trial)).as_matrix()
        e = ellipsoid(rng.normal(0, 0.3, 3) + np.array([0, 0, 1.0]), rng.uniform(0.05, 0.6, 3), rotation=R)
        frags = rasterize([e], [AT_ORIGIN], SMALL, 64, 48)
        ref = ray_hits(e, AT_ORIGIN, SMALL)
        differing += int(np.count_nonzero(hit_image(frags) != ref))
        total += int(ref.sum())
        # each depth is the first root: the point is on the surface, and the ray is outside just before it
        v, u = np.divmod(frags.pixel, 64)
        d = np.stack([(u - SMALL.cx) / SMALL.fx, (v - SMALL.cy) / SMALL.fy, np.ones(len(u))], axis=1)
        on = d * frags.depth[:, None]
        before = d * (frags.depth[:, None] - 1e-3)
        q = np.einsum("ni,ij,nj->n", on - e.center, e.shape_matrix, on - e.center)
        q_before = np.einsum("ni,ij,nj->n", before - e.center, e.shape_matrix, before - e.center)
        front = frags.depth > 0
        np.testing.assert_allclose(q[front], 1.0, atol=1e-3)
        assert np.all(q_before[front] > 1.0)
    assert total > 20_000
    assert differing <= 1e-3 * total  # float32 tiles: a rare boundary pixel may flip


def test_nearer_sphere_has_smaller_depth_at_the_centre_pixel() -> None:
    near, far = ellipsoid([0, 0, 0.5], [0.05] * 3), ellipsoid([0, 0, 0.9], [0.2] * 3)
    frags = rasterize([near, far], [AT_ORIGIN], Intrinsics(width=63, height=47, fx=50, fy=50, cx=31, cy=23), 63, 47)
    centre = 23 * 63 + 31
    at = frags.pixel == centre
    depth = dict(zip(frags.ellipsoid[at].tolist(), frags.depth[at].tolist(), strict=True))
    assert depth[0] == pytest.approx(0.45, abs=1e-5) and depth[1] == pytest.approx(0.70, abs=1e-5)


def test_camera_inside_covers_every_pixel_at_depth_zero_and_behind_covers_none() -> None:
    around = ellipsoid([0, 0, 0.1], [0.5, 0.5, 0.5])
    behind = ellipsoid([0, 0, -1.0], [0.2, 0.2, 0.2])
    frags = rasterize([around, behind], [AT_ORIGIN], SMALL, 16, 12)
    assert frags.inside.tolist() == [[True, False]]
    assert np.all(frags.ellipsoid == 0) and len(frags.pixel) == 16 * 12
    assert np.all(frags.depth == 0.0)


def test_ellipsoid_across_the_image_plane_hits_the_exact_pixels() -> None:
    e = ellipsoid([0.25, 0.0, 0.05], [0.2, 0.1, 0.2])  # crosses z = 0, camera outside
    frags = rasterize([e], [AT_ORIGIN], SMALL, 64, 48)
    ref = ray_hits(e, AT_ORIGIN, SMALL)
    assert 0 < ref.sum() < 64 * 48
    assert np.count_nonzero(hit_image(frags) != ref) <= 2


def test_several_cameras_at_once_equal_one_at_a_time() -> None:
    ells = [ellipsoid([0.05, 0, 0.5], [0.05, 0.08, 0.03]), ellipsoid([-0.05, 0.02, 0.6], [0.1, 0.04, 0.05], "frontier")]
    poses = [AT_ORIGIN, Pose.look_at([0.4, 0.0, 0.5], [0.0, 0.0, 0.55]), Pose.look_at([0, 0.3, 0.1], [0, 0, 0.55])]
    both = rasterize(ells, poses, SMALL, 32, 24)
    for c, pose in enumerate(poses):
        one = rasterize(ells, [pose], SMALL, 32, 24)
        for e in range(2):
            np.testing.assert_array_equal(hit_image(both, c, e), hit_image(one, 0, e))


def test_focus_limits_the_other_ellipsoids_to_the_box_of_the_focus_ones() -> None:
    big = ellipsoid([0, 0, 1.0], [0.5, 0.5, 0.1])
    small = ellipsoid([0.1, 0.05, 0.8], [0.03, 0.03, 0.03], "frontier")
    focus = np.array([False, True])
    frags = rasterize([big, small], [AT_ORIGIN], SMALL, 64, 48, focus=focus)
    full = rasterize([big, small], [AT_ORIGIN], SMALL, 64, 48)
    small_img = hit_image(full, 0, 1)
    rows, cols = np.nonzero(small_img)
    box = np.zeros_like(small_img)
    box[rows.min() : rows.max() + 1, cols.min() : cols.max() + 1] = True
    np.testing.assert_array_equal(hit_image(frags, 0, 1), small_img)  # the focus ellipsoid is whole
    np.testing.assert_array_equal(hit_image(frags, 0, 0), hit_image(full, 0, 0) & box)
    away = rasterize([big, small], [Pose.look_at([0, 0, 0], [0, 0, -1])], SMALL, 64, 48, focus=focus)
    assert len(away.pixel) == 0  # no focus ellipsoid in view: nothing is drawn


@pytest.mark.parametrize(
    ("kwargs", "field"),
    [
        ({"width": 0}, "width"),
        ({"height": 2.5}, "height"),
        ({"width": True}, "width"),
        ({"focus": np.array([True, False, True])}, "focus"),
        ({"ellipsoids": ["not one"]}, "ellipsoids[0]"),
        ({"poses": [np.eye(4)]}, "poses[0]"),
        ({"intrinsics": (640, 480)}, "intrinsics"),
    ],
)
def test_bad_input_names_the_field(kwargs: dict, field: str) -> None:
    args = {
        "ellipsoids": [ellipsoid([0, 0, 1.0], [0.1] * 3)],
        "poses": [AT_ORIGIN],
        "intrinsics": SMALL,
        "width": 8,
        "height": 6,
    }
    args.update(kwargs)
    with pytest.raises(ValueError, match="^" + re.escape(field) + ":"):
        rasterize(**args)
