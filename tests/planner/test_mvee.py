"""Minimum-volume enclosing ellipsoids: known answers, containment, batching, bad input."""

from __future__ import annotations

import numpy as np
import pytest

from planner.mvee import mvee, mvee_batch


def _rotation(a: float, b: float, c: float) -> np.ndarray:
    ca, sa, cb, sb, cc, sc = np.cos(a), np.sin(a), np.cos(b), np.sin(b), np.cos(c), np.sin(c)
    rx = np.array([[1, 0, 0], [0, ca, -sa], [0, sa, ca]])
    ry = np.array([[cb, 0, sb], [0, 1, 0], [-sb, 0, cb]])
    rz = np.array([[cc, -sc, 0], [sc, cc, 0], [0, 0, 1]])
    return rz @ ry @ rx


def _semi_axes(A: np.ndarray) -> np.ndarray:
    return np.sort(1.0 / np.sqrt(np.linalg.eigvalsh(A)))[::-1]


def _reach(points: np.ndarray, c: np.ndarray, A: np.ndarray) -> np.ndarray:
    d = points - c
    return np.einsum("ni,ij,nj->n", d, A, d)


def test_recovers_an_ellipsoid_from_its_surface_points() -> None:
    rng = np.random.default_rng(3)
    v = rng.normal(size=(500, 3))
    v /= np.linalg.norm(v, axis=1, keepdims=True)
    R, c0 = _rotation(0.3, -0.5, 1.0), np.array([1.0, -2.0, 0.5])
    pts = (v * [3.0, 2.0, 0.5]) @ R.T + c0
    c, A = mvee(pts, tol=1e-5)
    np.testing.assert_allclose(c, c0, atol=2e-3)
    np.testing.assert_allclose(_semi_axes(A), [3.0, 2.0, 0.5], rtol=2e-3)
    # the principal directions too: A ~ R diag(axes^-2) R^T
    np.testing.assert_allclose(A, R @ np.diag([3.0**-2, 2.0**-2, 0.5**-2]) @ R.T, atol=5e-3 * np.abs(A).max())


def test_box_corners_give_sqrt3_times_the_half_extents() -> None:
    half = np.array([0.4, 0.2, 0.1])
    corners = np.array([[x, y, z] for x in (-1, 1) for y in (-1, 1) for z in (-1, 1)]) * half + [5.0, 0.0, -1.0]
    c, A = mvee(corners, tol=1e-7)
    np.testing.assert_allclose(c, [5.0, 0.0, -1.0], atol=1e-6)
    np.testing.assert_allclose(_semi_axes(A), np.sqrt(3.0) * half, rtol=1e-5)


def test_regular_tetrahedron_gives_its_circumsphere() -> None:
    tet = np.array([[1, 1, 1], [1, -1, -1], [-1, 1, -1], [-1, -1, 1]], dtype=float)
    c, A = mvee(tet, tol=1e-8)
    np.testing.assert_allclose(c, 0.0, atol=1e-7)
    np.testing.assert_allclose(A, np.eye(3) / 3.0, atol=1e-6)  # radius sqrt(3)


def test_contains_every_point_and_touches_the_farthest() -> None:
    rng = np.random.default_rng(0)
    pts = rng.uniform(-1, 1, size=(400, 3)) * [5.0, 2.0, 1.0]
    c, A = mvee(pts, tol=1e-3)
    r = _reach(pts, c, A)
    assert r.max() <= 1.0 + 1e-9
    assert r.max() >= 1.0 - 1e-9  # tight: scaled so the farthest point is on the surface
    assert np.allclose(A, A.T)
    assert np.all(np.linalg.eigvalsh(A) > 0)


def test_is_affine_equivariant() -> None:
    rng = np.random.default_rng(1)
    pts = rng.normal(size=(60, 3))
    M, t = _rotation(0.2, 0.4, -0.7) @ np.diag([2.0, 1.0, 0.3]), np.array([10.0, -3.0, 4.0])
    c1, A1 = mvee(pts, tol=1e-8, max_iter=20000)
    c2, A2 = mvee(pts @ M.T + t, tol=1e-8, max_iter=20000)
    np.testing.assert_allclose(c2, M @ c1 + t, atol=1e-4)
    Minv = np.linalg.inv(M)
    np.testing.assert_allclose(A2, Minv.T @ A1 @ Minv, rtol=1e-3, atol=1e-5)


def test_batch_matches_single_sets() -> None:
    rng = np.random.default_rng(2)
    sets = [rng.normal(size=(n, 3)) * rng.uniform(0.5, 3, size=3) + rng.normal(size=3) for n in (5, 30, 80)]
    centers, A = mvee_batch(sets, tol=1e-7, max_iter=20000)
    for s, c, a in zip(sets, centers, A, strict=True):
        c1, a1 = mvee(s, tol=1e-7, max_iter=20000)
        np.testing.assert_allclose(c, c1, atol=1e-4)
        np.testing.assert_allclose(a, a1, rtol=1e-3, atol=1e-6)
        assert _reach(s, c, a).max() <= 1.0 + 1e-9


def test_warmup_keeps_containment_and_near_minimal_volume() -> None:
    rng = np.random.default_rng(4)
    pts = rng.uniform(-1, 1, size=(60, 3)) * [3.0, 1.0, 0.5]
    _, A_ref = mvee_batch([pts], tol=1e-8, max_iter=50000)
    c, A = mvee_batch([pts], tol=1e-3, max_iter=30, warmup=50)
    assert _reach(pts, c[0], A[0]).max() <= 1.0 + 1e-9
    ratio = np.sqrt(np.linalg.det(A_ref[0]) / np.linalg.det(A[0]))  # volume ratio
    assert 1.0 - 1e-9 <= ratio < 1.05


def test_bad_input_names_the_problem() -> None:
    with pytest.raises(ValueError, match="points: expected shape"):
        mvee(np.zeros((5, 2)))
    with pytest.raises(ValueError, match="points: 1 non-finite"):
        mvee(np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0], [0, 0, np.nan]]))
    with pytest.raises(ValueError, match="at least 4 points"):
        mvee(np.eye(3))
    with pytest.raises(ValueError, match="degenerate"):
        mvee(np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0], [1, 1, 0], [2, 3, 0]], dtype=float))
    with pytest.raises(ValueError, match="tol: must be"):
        mvee(np.vstack([np.eye(3), np.zeros(3)]), tol=0.0)
    with pytest.raises(ValueError, match=r"point_sets\[1\]: expected shape"):
        mvee_batch([np.eye(4, 3), np.zeros(3)])
    assert mvee_batch([])[0].shape == (0, 3)


def test_batch_rejects_a_flat_set_by_index() -> None:
    good = np.vstack([np.eye(3), np.zeros(3)])
    flat = np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0], [1, 1, 0]], dtype=float)
    with pytest.raises(ValueError, match=r"point_sets\[1\]: affinely degenerate"):
        mvee_batch([good, flat])
