"""Dual quadric -> conic, the analytic clipped area and the raster references."""

from __future__ import annotations

import math

import numpy as np
import pytest

from planner.projection import (
    BEHIND,
    FRONT,
    INSIDE,
    STRADDLE,
    conic_from_dual,
    disk_polygon_area,
    dual_conics,
    ellipse_from_dual,
    ellipse_rect_area,
    project,
    projection_matrix,
    raster_pixels,
    ray_hit_count,
    ray_hits,
)
from planner.types import Ellipsoid, Intrinsics, Pose

K = Intrinsics()  # 640 x 480, f = 610
SMALL = Intrinsics(width=64, height=48, fx=40.0, fy=40.0, cx=31.5, cy=23.5)


def rotation(rng: np.random.Generator) -> np.ndarray:
    q, _ = np.linalg.qr(rng.normal(size=(3, 3)))
    return q * np.sign(np.linalg.det(q))


def sphere(center, r: float, kind: str = "occupied") -> Ellipsoid:
    return Ellipsoid(np.asarray(center, float), np.full(3, r), np.eye(3), kind)  # type: ignore[arg-type]


def count_inside(center: np.ndarray, S: np.ndarray, width: int, height: int) -> int:
    """Brute force: pixel centres (u, v) of the whole image inside the ellipse."""
    u, v = np.meshgrid(np.arange(width, dtype=float), np.arange(height, dtype=float))
    d = np.stack([u - center[0], v - center[1]], axis=-1)
    return int(np.count_nonzero(np.einsum("...i,ij,...j->...", d, np.linalg.inv(S), d) <= 1.0))


# ----------------------------------------------------------------------------- P and the conic


def test_projection_matrix_maps_a_known_point() -> None:
    pose = Pose.look_at([1.0, 0.0, 0.0], [0.0, 0.0, 0.0])  # looks along -x, world z up = image -y
    P = projection_matrix(pose, K)
    p = P @ np.array([0.0, 0.0, 0.1, 1.0])
    np.testing.assert_allclose(p[:2] / p[2], [319.5, 239.5 - 610.0 * 0.1 / 1.0])
    np.testing.assert_allclose(p[2], 1.0)  # depth


def test_sphere_head_on_is_a_circle_of_the_pinhole_radius() -> None:
    r, d = 0.05, 0.5
    pose = Pose.identity()  # camera at the origin looking along +z
    e = sphere([0.0, 0.0, d], r)
    rho = K.fx * r / math.sqrt(d * d - r * r)
    dual = dual_conics(projection_matrix(pose, K)[None], e.dual()[None])[0, 0]
    center, S = ellipse_from_dual(dual)
    np.testing.assert_allclose(center, [K.cx, K.cy], atol=1e-9)
    np.testing.assert_allclose(S, rho**2 * np.eye(2), rtol=1e-12)
    conic = conic_from_dual(dual)
    on = np.array([K.cx + rho, K.cy, 1.0])
    assert abs(on @ conic @ on) < 1e-9
    assert np.array([K.cx, K.cy, 1.0]) @ conic @ np.array([K.cx, K.cy, 1.0]) == pytest.approx(-1.0)
    fast = project([e], [pose], K)
    assert fast.status[0, 0] == FRONT
    np.testing.assert_allclose(fast.ellipse_center[0, 0], [K.cx, K.cy], atol=1e-9)
    np.testing.assert_allclose(fast.ellipse_shape[0, 0], rho**2 * np.eye(2), rtol=1e-12)
    assert fast.pixels[0, 0] == pytest.approx(math.pi * rho**2, rel=1e-12)  # wholly inside the image


def contour_points(e: Ellipsoid, eye: np.ndarray, n: int = 64) -> np.ndarray:
    """(n, 3) points where rays from ``eye`` graze ``e``: the ellipsoid cut by the polar plane of eye."""
    plane = e.as_quadric() @ np.append(eye, 1.0)  # n . X + d = 0
    nrm, d = plane[:3], plane[3]
    m = e.axes * (e.rotation.T @ nrm)  # X = c + R diag(a) u, |u| = 1  ->  m . u = k
    k = -(nrm @ e.center + d)
    m_hat = m / np.linalg.norm(m)
    e1 = np.cross(m_hat, [1.0, 0.0, 0.0] if abs(m_hat[0]) < 0.9 else [0.0, 1.0, 0.0])
    e1 /= np.linalg.norm(e1)
    e2 = np.cross(m_hat, e1)
    h = k / np.linalg.norm(m)
    th = np.linspace(0, 2 * np.pi, n, endpoint=False)[:, None]
    u = h * m_hat + math.sqrt(1 - h * h) * (np.cos(th) * e1 + np.sin(th) * e2)
    return e.center + (u * e.axes) @ e.rotation.T


def test_off_axis_ellipsoid_conic_passes_through_projected_tangent_points() -> None:
    rng = np.random.default_rng(3)
    e = Ellipsoid(np.array([0.12, -0.05, 0.1]), np.array([0.08, 0.03, 0.05]), rotation(rng), "frontier")
    pose = Pose.look_at([0.5, 0.3, 0.35], [0.0, 0.0, 0.1])
    P = projection_matrix(pose, K)
    X = contour_points(e, pose.translation)
    assert np.allclose(np.einsum("ni,ij,nj->n", X - e.center, e.shape_matrix, X - e.center), 1.0)
    p = np.hstack([X, np.ones((len(X), 1))]) @ P.T
    p /= p[:, 2:3]
    conic = conic_from_dual(dual_conics(P[None], e.dual()[None])[0, 0])
    np.testing.assert_allclose(np.einsum("ni,ij,nj->n", p, conic, p), 0.0, atol=1e-9)
    fast = project([e], [pose], K)
    d = p[:, :2] - fast.ellipse_center[0, 0]
    np.testing.assert_allclose(np.einsum("ni,ij,nj->n", d, np.linalg.inv(fast.ellipse_shape[0, 0]), d), 1.0, rtol=1e-9)
    # every surface point projects inside or on the outline, and the outline is reached
    g = rng.normal(size=(20000, 3))
    g /= np.linalg.norm(g, axis=1, keepdims=True)
    Y = e.center + (g * e.axes) @ e.rotation.T
    q = np.hstack([Y, np.ones((len(Y), 1))]) @ P.T
    dq = q[:, :2] / q[:, 2:3] - fast.ellipse_center[0, 0]
    s = np.einsum("ni,ij,nj->n", dq, np.linalg.inv(fast.ellipse_shape[0, 0]), dq)
    assert s.max() <= 1.0 + 1e-9
    assert s.max() > 0.999


def test_fast_closed_form_equals_the_paper_dual_for_many_pairs() -> None:
    rng = np.random.default_rng(4)
    ells = [
        Ellipsoid(rng.uniform(-0.1, 0.1, 3), rng.uniform(0.01, 0.06, 3), rotation(rng), "occupied") for _ in range(7)
    ]
    poses = [Pose.look_at(0.6 * np.r_[np.cos(a), np.sin(a), 0.6], rng.uniform(-0.05, 0.05, 3)) for a in range(5)]
    fast = project(ells, poses, K)
    assert np.all(fast.status == FRONT)
    P = np.stack([projection_matrix(p, K) for p in poses])
    center, S = ellipse_from_dual(dual_conics(P, np.stack([e.dual() for e in ells])))
    np.testing.assert_allclose(fast.ellipse_center, center, rtol=1e-9, atol=1e-7)
    np.testing.assert_allclose(fast.ellipse_shape, S, rtol=1e-8, atol=1e-6)


# ----------------------------------------------------------------------------- areas


def test_disk_polygon_area_known_values() -> None:
    def rect(x0: float, x1: float, y0: float, y1: float) -> list[list[float]]:
        return [[x0, y0], [x1, y0], [x1, y1], [x0, y1]]  # counter-clockwise

    polys = np.array(
        [
            rect(-0.5, 0.5, -0.5, 0.5),  # inside the disk: the square
            rect(-2, 2, -2, 2),  # around the disk: pi
            rect(0, 10, -10, 10),  # half disk
            rect(-0.5, 0.5, -5, 5),  # strip |x| <= 1/2
            rect(2, 3, -1, 1),  # disjoint
            rect(1e6, 2e6, -1e6, 1e6),  # far away and huge
            rect(-1e6, 1e6, -1e6, 1e6),  # huge, around
        ]
    )
    strip = 2 * (0.5 * math.sqrt(0.75) + math.asin(0.5))
    want = [1.0, math.pi, math.pi / 2, strip, 0.0, 0.0, math.pi]
    np.testing.assert_allclose(disk_polygon_area(polys), want, atol=1e-9)
    np.testing.assert_allclose(disk_polygon_area(polys[:, ::-1]), -np.array(want), atol=1e-9)  # clockwise


@pytest.mark.parametrize(
    ("center", "axes", "angle"),
    [
        ((320.0, 240.0), (60.0, 25.0), 0.3),  # inside
        ((5.0, 100.0), (40.0, 30.0), 1.0),  # clipped by the left edge
        ((630.0, 470.0), (80.0, 50.0), -0.4),  # clipped at a corner
        ((320.0, -20.0), (400.0, 60.0), 0.1),  # wider than the image, clipped top
        ((300.0, 250.0), (5000.0, 3000.0), 0.7),  # covers the image
        ((-700.0, 240.0), (1000.0, 400.0), 0.2),  # huge, boundary crosses the image
    ],
)
def test_analytic_area_matches_pixel_count(center, axes, angle) -> None:
    c, s = math.cos(angle), math.sin(angle)
    R = np.array([[c, -s], [s, c]])
    S = R @ np.diag(np.square(axes)) @ R.T
    got = ellipse_rect_area(np.array([center]), S[None], K.width, K.height)[0]
    want = count_inside(np.array(center), S, K.width, K.height)
    assert want > 200
    assert got == pytest.approx(want, rel=0.01)
    assert got <= K.width * K.height + 1e-6


def test_analytic_area_of_an_ellipse_inside_is_pi_a_b_and_outside_is_zero() -> None:
    S = np.array([[[9.0, 0.0], [0.0, 4.0]], [[9.0, 0.0], [0.0, 4.0]]])
    got = ellipse_rect_area(np.array([[100.0, 100.0], [-50.0, 100.0]]), S, K.width, K.height)
    np.testing.assert_allclose(got, [6 * math.pi, 0.0], atol=1e-9)


def test_raster_and_analytic_agree_on_real_views() -> None:
    e = Ellipsoid(np.array([0.0, 0.0, 0.1]), np.array([0.08, 0.05, 0.04]), np.eye(3), "occupied")
    poses = [
        Pose.look_at([0.5, 0.1, 0.3], [0.0, 0.0, 0.1]),  # inside the image
        Pose.look_at([0.5, 0.1, 0.3], [0.0, 0.3, 0.1]),  # partly out of view (left edge)
        Pose.look_at([0.1, 0.02, 0.11], [0.0, 0.05, 0.1]),  # very close: far larger than the image
    ]
    fast = project([e], poses, K)
    ref = np.array([raster_pixels(e, p, K) for p in poses])
    assert np.all(fast.status[:, 0] == FRONT)
    half_u = np.sqrt(fast.ellipse_shape[:, 0, 0, 0])
    assert fast.ellipse_center[1, 0, 0] - half_u[1] < -0.5 < fast.ellipse_center[1, 0, 0] + half_u[1]
    assert 200 < ref[1] < math.pi * np.sqrt(np.linalg.det(fast.ellipse_shape[1, 0])) - 200
    assert 200 < ref[0] < K.width * K.height
    assert math.pi * np.sqrt(np.linalg.det(fast.ellipse_shape[2, 0])) > 2 * K.width * K.height  # far larger ...
    assert K.width * K.height / 4 < ref[2] < K.width * K.height  # ... and its outline crosses the image
    np.testing.assert_allclose(fast.pixels[:, 0], ref, rtol=0.01)
    # the conic raster agrees exactly with the per-pixel ray test
    assert [int(ray_hits(e, p, K).sum()) for p in poses] == ref.tolist()


# ----------------------------------------------------------------------------- behind, inside, straddling


def test_ellipsoid_behind_the_camera_contributes_nothing() -> None:
    e = sphere([0.0, 0.0, -0.5], 0.05)
    pose = Pose.identity()
    # the algebra alone would still give an ellipse (the virtual image through the pinhole)
    center, S = ellipse_from_dual(dual_conics(projection_matrix(pose, K)[None], e.dual()[None])[0, 0])
    assert np.all(np.linalg.eigvalsh(S) > 0) and np.allclose(center, [K.cx, K.cy])
    fast = project([e], [pose], K)
    assert fast.status[0, 0] == BEHIND and fast.pixels[0, 0] == 0.0
    assert raster_pixels(e, pose, K) == 0 and not ray_hits(e, pose, K).any()


def test_camera_inside_sees_the_ellipsoid_everywhere() -> None:
    e = sphere([0.0, 0.0, 0.02], 0.1)
    fast = project([e], [Pose.identity()], K)
    assert fast.status[0, 0] == INSIDE and fast.pixels[0, 0] == K.width * K.height
    assert raster_pixels(e, Pose.identity(), K) == K.width * K.height


def ray_march_count(e: Ellipsoid, k: Intrinsics) -> int:
    """Independent brute force: sample each pixel ray densely, look for a point inside."""
    u, v = np.meshgrid(np.arange(k.width, dtype=float), np.arange(k.height, dtype=float))
    d = np.stack([(u - k.cx) / k.fx, (v - k.cy) / k.fy, np.ones_like(u)], axis=-1).reshape(-1, 1, 3)
    s = np.linspace(1e-3, 0.5, 1000)[None, :, None]  # the ellipsoid lies within 0.5 m of the camera
    pts = (s * d).reshape(-1, 3)  # camera at the origin, identity pose
    return int(e.contains(pts).reshape(len(d), -1).any(axis=1).sum())


def test_straddling_ellipsoid_is_rasterised_by_rays() -> None:
    e = Ellipsoid(np.array([0.15, 0.0, 0.05]), np.array([0.08, 0.05, 0.3]), np.eye(3), "frontier")  # z: -0.25..0.35
    pose = Pose.identity()
    dual = dual_conics(projection_matrix(pose, SMALL)[None], e.dual()[None])[0, 0]
    assert dual[2, 2] > 0  # not an ellipse
    fast = project([e], [pose], SMALL)
    assert fast.status[0, 0] == STRADDLE
    want = ray_march_count(e, SMALL)
    assert want > 100
    assert fast.pixels[0, 0] == raster_pixels(e, pose, SMALL)
    assert abs(fast.pixels[0, 0] - want) <= 3  # grazing rays may fall between the march samples


def test_many_pairs_mixed_cases_match_raster() -> None:
    ells = [
        sphere([0.0, 0.0, 0.5], 0.05),  # front
        sphere([0.0, 0.0, -0.5], 0.05),  # behind
        sphere([0.0, 0.0, 0.02], 0.1),  # inside
        Ellipsoid(np.array([0.15, 0.0, 0.05]), np.array([0.08, 0.05, 0.3]), np.eye(3), "frontier"),  # straddle
    ]
    poses = [Pose.identity(), Pose.look_at([0.0, 0.0, 0.0], [0.0, 0.0, -1.0])]  # forward and backward
    fast = project(ells, poses, SMALL)
    np.testing.assert_array_equal(fast.status, [[FRONT, BEHIND, INSIDE, STRADDLE], [BEHIND, FRONT, INSIDE, STRADDLE]])
    raster = project(ells, poses, SMALL, area="raster")
    np.testing.assert_allclose(fast.pixels, raster.pixels, rtol=0.05)  # the spheres are ~90 px here
    assert fast.pixels[0, 0] == fast.pixels[1, 1]  # symmetric views of symmetric spheres


def test_bad_input_raises() -> None:
    with pytest.raises(ValueError, match="ellipsoids\\[0\\]"):
        project(["nope"], [Pose.identity()], K)  # type: ignore[list-item]
    with pytest.raises(ValueError, match="poses\\[0\\]"):
        project([sphere([0, 0, 1], 0.1)], [np.eye(4)], K)  # type: ignore[list-item]
    with pytest.raises(ValueError, match="area"):
        project([], [], K, area="exact")  # type: ignore[arg-type]
    with pytest.raises(ValueError, match="S"):
        ellipse_rect_area(np.zeros((2, 2)), np.zeros((3, 2, 2)), 10, 10)
    with pytest.raises(ValueError, match="P"):
        dual_conics(np.zeros((3, 4)), np.zeros((1, 4, 4)))


def test_empty_inputs() -> None:
    assert project([], [Pose.identity()], K).pixels.shape == (1, 0)
    assert project([sphere([0, 0, 1], 0.1)], [], K).pixels.shape == (0, 1)


def test_random_views_analytic_within_one_percent_of_raster() -> None:
    rng = np.random.default_rng(11)
    up = np.array([0.0, 0.0, 0.1])
    ells = [
        Ellipsoid(rng.uniform(-0.1, 0.1, 3) + up, rng.uniform(0.02, 0.08, 3), rotation(rng), "occupied")
        for _ in range(6)
    ]
    poses = [Pose.look_at(c + up, rng.uniform(-0.15, 0.15, 3) + up) for c in rng.normal(size=(6, 3)) * [0.3, 0.3, 0.1]]
    fast = project(ells, poses, K)
    ref = np.array([[raster_pixels(e, p, K) for e in ells] for p in poses])
    big = ref > 1000
    assert big.sum() >= 10
    np.testing.assert_allclose(fast.pixels[big], ref[big], rtol=0.01)
    np.testing.assert_allclose(fast.pixels[~big], ref[~big], atol=60)


def test_row_by_row_ray_count_equals_the_per_pixel_test() -> None:
    rng = np.random.default_rng(5)
    seen = set()
    for i in range(120):
        e = Ellipsoid(rng.normal(size=3) * 0.3, rng.uniform(0.01, 0.4, 3), rotation(rng), "occupied")
        pose = Pose.look_at(rng.normal(size=3) * 0.3, rng.normal(size=3) * 0.3)
        k = K if i % 10 == 0 else SMALL
        seen.add(int(project([e], [pose], k).status[0, 0]))
        assert ray_hit_count(e, pose, k) == int(ray_hits(e, pose, k).sum())
    assert seen == {FRONT, BEHIND, STRADDLE, INSIDE}
