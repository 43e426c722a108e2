"""EllipsoidFitter: containment, minimum thickness, the ClusterFit record, warm state, bad input."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest
import trimesh

from planner.config import ClusterConfig
from planner.ellipsoids import EllipsoidFitter
from planner.mixture import assign
from planner.types import Ellipsoid

RES = 0.01
CFG = dataclasses.replace(ClusterConfig(), t_min=2, t_max=12)


@pytest.fixture(scope="module")
def sphere_voxels() -> np.ndarray:
    """~450 surface voxels of a sphere of radius 6 cm centred at (0.1, -0.05, 0.08)."""
    mesh = trimesh.creation.icosphere(subdivisions=4, radius=0.06).apply_translation([0.1, -0.05, 0.08])
    p = trimesh.sample.sample_surface(mesh, 40_000, seed=0)[0]
    return np.unique(np.round(p / RES).astype(np.int64), axis=0).astype(float) * RES


def _cluster_members(fitter: EllipsoidFitter, points: np.ndarray, ellipsoids: tuple[Ellipsoid, ...]) -> list:
    """Each ellipsoid's voxels, matched by the component whose GMM mean it carries."""
    assert fitter.mixture is not None
    labels = assign(points / RES, fitter.mixture)
    out = []
    for e in ellipsoids:
        assert e.gmm_mean is not None
        comp = int(np.argmin(np.linalg.norm(fitter.mixture.means * RES - e.gmm_mean, axis=1)))
        out.append(points[labels == comp])
    return out


def test_every_voxel_centre_is_inside_its_clusters_ellipsoid(sphere_voxels: np.ndarray) -> None:
    fitter = EllipsoidFitter(CFG, RES, "occupied")
    ellipsoids, fit = fitter.fit(sphere_voxels)
    members = _cluster_members(fitter, sphere_voxels, ellipsoids)
    assert sum(len(m) for m in members) == len(sphere_voxels)
    for e, m in zip(ellipsoids, members, strict=True):
        assert e.n_points == len(m) > 0
        assert e.kind == "occupied"
        assert e.contains(m, tol=1e-9).all()
        # the voxel cubes too: every corner of every voxel
        corners = (m[:, None, :] + RES / 2 * np.array(np.meshgrid(*[[-1, 1]] * 3)).reshape(3, -1).T).reshape(-1, 3)
        assert e.contains(corners, tol=1e-9).all()
        assert e.axes.min() >= RES / 2
        assert np.linalg.det(e.rotation) == pytest.approx(1.0)
        assert np.all(np.diff(e.axes) <= 0)  # major axis first
        # GMM parameters in metres: the mean is the cluster's centroid (up to soft assignment)
        assert e.gmm_mean is not None and e.gmm_covariance is not None
        assert np.linalg.norm(e.gmm_mean - m.mean(axis=0)) < 0.01
        assert np.all(np.linalg.eigvalsh(e.gmm_covariance) >= RES**2 / 12 * 0.999)
    assert fit.kind == "occupied" and fit.n_points == len(sphere_voxels)
    assert fit.t_chosen == fitter.mixture.n_components >= len(ellipsoids)  # type: ignore[union-attr]
    ts = [t for t, _ in fit.bic]
    assert ts == sorted(ts) and fit.t_chosen in ts
    assert dict(fit.bic)[fit.t_chosen] == min(b for _, b in fit.bic)
    assert fit.seconds > 0
    assert set(fitter.last_timings) == {"cluster", "ellipsoids"}
    assert fit.seconds == pytest.approx(sum(fitter.last_timings.values()), rel=1e-6)


def test_ellipsoids_are_near_minimal(sphere_voxels: np.ndarray) -> None:
    """Each cluster's ellipsoid is within a few per cent of the converged MVEE of its voxel cubes."""
    from planner.mvee import mvee

    fitter = EllipsoidFitter(CFG, RES, "frontier")
    ellipsoids, _ = fitter.fit(sphere_voxels)
    offsets = RES / 2 * np.array([[x, y, z] for x in (-1, 1) for y in (-1, 1) for z in (-1, 1)])
    for e, m in zip(ellipsoids, _cluster_members(fitter, sphere_voxels, ellipsoids), strict=True):
        _, A = mvee((m[:, None, :] + offsets).reshape(-1, 3), tol=1e-6, max_iter=50_000)
        exact = 4.0 / 3.0 * np.pi / np.sqrt(np.linalg.det(A))
        assert 1.0 - 1e-6 <= e.volume / exact < 1.08


def test_single_voxel_gives_the_sphere_around_its_cube() -> None:
    (e,), fit = EllipsoidFitter(CFG, RES, "frontier").fit(np.array([[0.2, 0.1, 0.05]]))
    np.testing.assert_allclose(e.center, [0.2, 0.1, 0.05], atol=1e-9)
    np.testing.assert_allclose(e.axes, np.sqrt(3) / 2 * RES, rtol=1e-3)  # >= res / 2
    assert e.kind == "frontier" and e.n_points == 1
    assert fit.t_chosen == 1 and fit.n_points == 1


def test_planar_and_collinear_sets_are_at_least_one_voxel_thick() -> None:
    g = np.arange(10) * RES
    plane = np.stack(np.meshgrid(g, g, [0.3], indexing="ij"), axis=-1).reshape(-1, 3)
    line = np.column_stack([g, np.zeros(10), np.zeros(10)])
    for points in (plane, line):
        fitter = EllipsoidFitter(CFG, RES, "occupied")
        ellipsoids, _ = fitter.fit(points)
        members = _cluster_members(fitter, points, ellipsoids)
        for e, m in zip(ellipsoids, members, strict=True):
            assert e.contains(m, tol=1e-9).all()
            assert e.axes.min() >= RES / 2 * (1 - 1e-9)
    # the plane's thin axis is along z and its extent covers the slab of voxel cubes
    (e, *_), _ = EllipsoidFitter(dataclasses.replace(CFG, t_min=1, t_max=1), RES, "occupied").fit(plane)
    assert abs(e.rotation[:, 2] @ [0, 0, 1]) == pytest.approx(1.0, abs=1e-6)
    assert e.axes[2] >= RES / 2


def test_empty_set_gives_nothing() -> None:
    fitter = EllipsoidFitter(CFG, RES, "frontier")
    ellipsoids, fit = fitter.fit(np.zeros((0, 3)))
    assert ellipsoids == ()
    assert (fit.t_chosen, fit.bic, fit.n_points, fit.kind) == (0, (), 0, "frontier")
    assert fitter.mixture is None


def test_warm_state_is_kept_and_reset(sphere_voxels: np.ndarray) -> None:
    fitter = EllipsoidFitter(CFG, RES, "occupied")
    prev = sphere_voxels[sphere_voxels[:, 2] < np.quantile(sphere_voxels[:, 2], 0.9)]
    fitter.fit(prev)
    first = fitter.mixture
    assert first is not None
    ellipsoids, fit = fitter.fit(sphere_voxels)
    assert fitter.mixture is not first
    assert sum(e.n_points for e in ellipsoids) == len(sphere_voxels)
    cold = EllipsoidFitter(CFG, RES, "occupied").fit(sphere_voxels)[1]
    assert len(fit.bic) <= len(cold.bic)  # the warm search evaluates fewer T
    fitter.reset()
    assert fitter.mixture is None and fitter.last_timings == {}
    again = fitter.fit(sphere_voxels)[1]
    assert again.bic == cold.bic  # after reset: the cold result, deterministically


def test_bad_input_names_the_problem(sphere_voxels: np.ndarray) -> None:
    fitter = EllipsoidFitter(CFG, RES, "occupied")
    bad = sphere_voxels.copy()
    bad[0, 0] = np.inf
    with pytest.raises(ValueError, match="points_world: 1 non-finite"):
        fitter.fit(bad)
    with pytest.raises(ValueError, match=r"points_world: expected shape \(N, 3\)"):
        fitter.fit(sphere_voxels.ravel())
    assert fitter.mixture is None  # state unchanged
    with pytest.raises(ValueError, match="resolution"):
        EllipsoidFitter(CFG, -1.0, "occupied")
    with pytest.raises(ValueError, match="kind"):
        EllipsoidFitter(CFG, RES, "empty")  # type: ignore[arg-type]


def _same(a: tuple[tuple[Ellipsoid, ...], object], b: tuple[tuple[Ellipsoid, ...], object]) -> bool:
    """Bit-identical ellipsoids, GMM parameters, model selections and labels."""
    (ea, fa), (eb, fb) = a, b
    if len(ea) != len(eb) or fa.bic != fb.bic or not np.array_equal(fa.labels, fb.labels):  # type: ignore[attr-defined]
        return False
    fields = ("center", "axes", "rotation", "gmm_mean", "gmm_covariance", "gmm_weight", "n_points", "kind")
    return all(np.array_equal(getattr(x, f), getattr(y, f)) for x, y in zip(ea, eb, strict=True) for f in fields)


def test_kinds_fitted_together_give_the_ellipsoids_of_one_at_a_time(sphere_voxels: np.ndarray) -> None:
    """enclose() solves both kinds' MVEEs in one batch: the same ellipsoids, bit for bit, as fitting each alone,
    warm starts included (two frames in a row), whatever the other kind holds (empty, one voxel, many)."""
    from planner.ellipsoids import enclose, fit_together

    rng = np.random.default_rng(3)
    cap = sphere_voxels[sphere_voxels[:, 2] > np.quantile(sphere_voxels[:, 2], 0.7)]
    others = [np.zeros((0, 3)), sphere_voxels[:1], cap, cap[rng.permutation(len(cap))[: len(cap) // 2]]]
    for other in others:
        alone = [EllipsoidFitter(CFG, RES, "occupied"), EllipsoidFitter(CFG, RES, "frontier")]
        together = [EllipsoidFitter(CFG, RES, "occupied"), EllipsoidFitter(CFG, RES, "frontier")]
        for frame in (sphere_voxels[sphere_voxels[:, 0] < 0.12], sphere_voxels):
            one = [alone[0].fit(frame), alone[1].fit(other)]
            both = enclose([together[0].cluster(frame), together[1].cluster(other)])
            assert all(_same(x, y) for x, y in zip(one, both, strict=True))
            assert together[0].last_timings["ellipsoids"] > 0.0
    fresh = EllipsoidFitter(CFG, RES, "occupied")
    assert _same(fit_together([(fresh, cap, None)])[0], EllipsoidFitter(CFG, RES, "occupied").fit(cap))
    # fitters with other MVEE settings are solved in their own batch, with their own settings
    loose = EllipsoidFitter(CFG, RES, "frontier", mvee_tol=1e-1, mvee_max_iter=2, mvee_warmup=1)
    mixed = enclose([EllipsoidFitter(CFG, RES, "occupied").cluster(sphere_voxels), loose.cluster(cap)])
    ref = EllipsoidFitter(CFG, RES, "frontier", mvee_tol=1e-1, mvee_max_iter=2, mvee_warmup=1).fit(cap)
    assert _same(mixed[1], ref)
    assert not _same(mixed[1], EllipsoidFitter(CFG, RES, "frontier").fit(cap))
