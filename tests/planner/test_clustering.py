"""GMM + BIC model selection: the BIC formula, the few-points rule, fidelity against scikit-learn."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest
import trimesh
from sklearn.mixture import GaussianMixture
from sklearn.mixture._gaussian_mixture import _compute_precision_cholesky

from planner.clustering import bic_gap, bic_sweep, select_mixture, t_range
from planner.config import ClusterConfig
from planner.mixture import Mixture, bic_value, n_parameters

RES = 0.01


def _voxels(points: np.ndarray) -> np.ndarray:
    return np.unique(np.round(points / RES).astype(np.int64), axis=0).astype(float) * RES


@pytest.fixture(scope="module")
def surface() -> np.ndarray:
    """~480 surface voxels (world metres) of a box with a cylinder on top."""
    box = trimesh.creation.box(extents=[0.12, 0.08, 0.08]).apply_translation([0, 0, 0.04])
    cyl = trimesh.creation.cylinder(radius=0.03, height=0.08, sections=48).apply_translation([0, 0, 0.12])
    p = np.vstack([trimesh.sample.sample_surface(m, 40_000, seed=i)[0] for i, m in enumerate((box, cyl))])
    inside_box = np.all(np.abs(p - [0, 0, 0.04]) < [0.06 - 1e-9, 0.04 - 1e-9, 0.04 - 1e-9], axis=1)
    inside_cyl = (np.hypot(p[:, 0], p[:, 1]) < 0.03 - 1e-9) & (np.abs(p[:, 2] - 0.12) < 0.04 - 1e-9)
    return _voxels(p[~(inside_box | inside_cyl)])


@pytest.fixture(scope="module")
def shell() -> np.ndarray:
    """Frontier-like: a one-voxel-thick spherical cap of radius 0.12 m (~400 voxels)."""
    g = np.arange(-14, 15)
    P = np.stack(np.meshgrid(g, g, g, indexing="ij"), axis=-1).reshape(-1, 3).astype(float)
    d = np.linalg.norm(P, axis=1)
    keep = (np.abs(d - 12.0) <= 0.5) & (P[:, 2] > 0.55 * d)
    return P[keep] * RES


def _blobs(k: int = 7, per: int = 60, seed: int = 0) -> np.ndarray:
    rng = np.random.default_rng(seed)
    angles = 2 * np.pi * np.arange(k) / k
    centres = np.column_stack([0.3 * np.cos(angles), 0.3 * np.sin(angles), 0.05 * np.arange(k)])
    return np.vstack([c + rng.normal(scale=0.02, size=(per, 3)) for c in centres])


def test_parameter_count_is_ten_t_minus_one_like_sklearn() -> None:
    for t in (1, 5, 50):
        gm = GaussianMixture(t, covariance_type="full")
        gm.means_ = np.zeros((t, 3))  # _n_parameters reads the mean shape only
        assert n_parameters(t) == 10 * t - 1 == gm._n_parameters()


def test_bic_value_equals_sklearn(surface: np.ndarray) -> None:
    x = surface / RES
    gm = GaussianMixture(4, covariance_type="full", reg_covar=1 / 12, random_state=0).fit(x)
    ours = bic_value(x, Mixture(np.asarray(gm.weights_), np.asarray(gm.means_), np.asarray(gm.covariances_)))
    assert ours == pytest.approx(gm.bic(x), rel=1e-9)


def test_reported_bic_of_the_fast_choice_is_sklearns(surface: np.ndarray) -> None:
    x = surface / RES
    sel = select_mixture(x, dataclasses.replace(ClusterConfig(), t_min=2, t_max=12))
    mix = sel.mixture
    gm = GaussianMixture(mix.n_components, covariance_type="full")
    gm.weights_, gm.means_, gm.covariances_ = mix.weights, mix.means, mix.covariances
    gm.precisions_cholesky_ = _compute_precision_cholesky(mix.covariances, "full")
    assert sel.bic == pytest.approx(gm.bic(x), rel=1e-6)
    assert sel.evaluated[mix.n_components] == sel.bic
    assert sel.bic == min(sel.evaluated.values())


def test_sweep_works_in_voxel_units(surface: np.ndarray) -> None:
    cfg = ClusterConfig()
    sweep = bic_sweep(surface, [3], cfg, RES)
    x = surface / RES
    gm = GaussianMixture(3, covariance_type="full", reg_covar=1 / 12, random_state=0, max_iter=100, tol=1e-3).fit(x)
    assert sweep[3] == pytest.approx(gm.bic(x), rel=1e-12)
    # the same voxels at another resolution give the same BIC
    assert bic_sweep(surface * 2.0, [3], cfg, 2 * RES)[3] == pytest.approx(sweep[3], rel=1e-9)


def test_bic_gap_per_voxel() -> None:
    assert bic_gap(110.0, {2: 120.0, 3: 100.0}, 50) == pytest.approx(0.2)
    with pytest.raises(ValueError, match="bic_gap"):
        bic_gap(1.0, {}, 10)


def test_chooses_seven_separated_blobs() -> None:
    x = _blobs() / RES
    for search in ("fast", "exhaustive"):
        cfg = dataclasses.replace(ClusterConfig(), t_min=2, t_max=12, search=search)
        sel = select_mixture(x, cfg)
        assert sel.mixture.n_components == 7, search
        assert np.allclose(np.sort(sel.mixture.weights), 1 / 7, atol=0.01)


@pytest.mark.parametrize("name", ["surface", "shell"])
def test_fast_search_is_within_the_bic_budget(name: str, request: pytest.FixtureRequest) -> None:
    points = request.getfixturevalue(name)
    cfg = dataclasses.replace(ClusterConfig(), t_min=2, t_max=12)
    sweep = bic_sweep(points, range(2, 13), cfg, RES)
    cold = select_mixture(points / RES, cfg)
    assert bic_gap(cold.bic, sweep, len(points)) <= 0.05
    assert len(cold.evaluated) < 11  # fewer fits than the sweep
    # warm: previous iteration saw 90 % of the voxels
    prev = points[points[:, 0] < np.quantile(points[:, 0], 0.9)]
    warm = select_mixture(points / RES, cfg, select_mixture(prev / RES, cfg).mixture)
    assert bic_gap(warm.bic, sweep, len(points)) <= 0.05
    assert len(warm.evaluated) <= len(cold.evaluated)


def test_exhaustive_reports_every_t_like_the_sweep(shell: np.ndarray) -> None:
    cfg = dataclasses.replace(ClusterConfig(), t_min=2, t_max=5, search="exhaustive")
    sel = select_mixture(shell / RES, cfg)
    sweep = bic_sweep(shell, range(2, 6), cfg, RES)
    assert sorted(sel.evaluated) == [2, 3, 4, 5]
    for t in sweep:
        assert sel.evaluated[t] == pytest.approx(sweep[t], rel=1e-12)
    assert sel.bic == min(sweep.values())


def test_deterministic(surface: np.ndarray) -> None:
    cfg = dataclasses.replace(ClusterConfig(), t_min=2, t_max=12)
    a, b = select_mixture(surface / RES, cfg), select_mixture(surface / RES, cfg)
    assert a.evaluated == b.evaluated
    np.testing.assert_array_equal(a.mixture.means, b.mixture.means)


def test_few_points_rule() -> None:
    cfg = ClusterConfig()  # t in [5, 50], 4 points per component
    assert t_range(0, cfg) == (0, 0)
    assert t_range(3, cfg) == (1, 1)
    assert t_range(12, cfg) == (3, 3)
    assert t_range(20, cfg) == (5, 5)
    assert t_range(100, cfg) == (5, 25)
    assert t_range(1000, cfg) == (5, 50)
    one = select_mixture(np.array([[3.0, 4.0, 5.0]]), cfg)
    assert one.mixture.n_components == 1
    np.testing.assert_allclose(one.mixture.means, [[3.0, 4.0, 5.0]])
    np.testing.assert_allclose(one.mixture.covariances[0], np.eye(3) / 12)  # just the floor
    ten = select_mixture(_blobs(k=2, per=5) / RES, cfg)
    assert 1 <= ten.mixture.n_components <= 2
    assert set(ten.evaluated) <= {1, 2}


def test_bad_input_names_the_problem(surface: np.ndarray) -> None:
    cfg = ClusterConfig()
    bad = surface.copy()
    bad[3, 1] = np.nan
    with pytest.raises(ValueError, match="points_world: 1 non-finite"):
        bic_sweep(bad, [2], cfg, RES)
    with pytest.raises(ValueError, match="points_world: expected shape"):
        bic_sweep(surface[:, :2], [2], cfg, RES)
    with pytest.raises(ValueError, match="resolution"):
        bic_sweep(surface, [2], cfg, 0.0)


def test_covariances_are_full_not_spherical() -> None:
    """The authors' code fits spherical Gaussians; the paper's ellipsoids need full covariances."""
    from planner.ellipsoids import EllipsoidFitter

    rng = np.random.default_rng(4)
    c, s = np.cos(np.pi / 4), np.sin(np.pi / 4)
    R = np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])
    local = rng.normal(size=(3000, 3)) * np.array([0.06, 0.01, 0.01])
    voxels = np.unique(np.floor((local @ R.T) / 0.01) * 0.01 + 0.005, axis=0)
    (ellipsoid,), fit = EllipsoidFitter(ClusterConfig(t_min=1, t_max=1), 0.01, "occupied").fit(voxels)
    assert fit.t_chosen == 1
    cov = ellipsoid.gmm_covariance
    assert cov is not None
    evals, evecs = np.linalg.eigh(cov)
    assert evals[-1] / evals[0] > 10.0  # elongated, not a sphere
    assert abs(abs(evecs[:, -1] @ np.array([c, s, 0.0])) - 1.0) < 0.02  # along the tilted axis
    assert cov[0, 1] > 0.3 * np.sqrt(cov[0, 0] * cov[1, 1])  # a real off-diagonal term
    long_axis = ellipsoid.rotation[:, np.argmax(ellipsoid.axes)]
    assert abs(abs(long_axis @ np.array([c, s, 0.0])) - 1.0) < 0.05


@pytest.mark.slow
def test_fast_search_never_chooses_or_reports_t_outside_the_range() -> None:
    """EM can lose a component on a small set; the model it falls back to (T < t_min) guides the
    search but is never chosen. Before this was pinned, 25 of these 300 sets chose T = 1 with t_min = 2."""
    cfg = dataclasses.replace(ClusterConfig(), t_min=2, t_max=6)
    checked = 0
    for seed in range(300):
        rng = np.random.default_rng(seed)
        n = int(rng.integers(8, 40))
        scale = np.array([1.0, 1.0, rng.uniform(0.1, 1.0)])
        pts = np.unique(np.round(rng.normal(0.0, rng.uniform(0.8, 3.0), (n, 3)) * scale), axis=0)
        lo, hi = t_range(len(pts), cfg)
        sel = select_mixture(pts, cfg)
        assert lo <= sel.mixture.n_components <= hi, seed
        assert all(lo <= t <= hi for t in sel.evaluated), (seed, sorted(sel.evaluated))
        checked += lo == 2
    assert checked > 250  # the range really starts at t_min = 2 for most sets


def test_k_means_draws_are_numpys_choice() -> None:
    """bic_search._draw (k-means++'s weighted pick without rng.choice's argument checks) draws what
    Generator.choice(N, size, p=p) draws, and leaves the generator in the same state."""
    from planner.bic_search import _draw

    for seed in range(100):
        ours, numpys = np.random.default_rng((seed, 3)), np.random.default_rng((seed, 3))
        n = 1 + 13 * seed
        p = np.random.default_rng(seed).random(n) ** 4
        p[np.random.default_rng(seed).random(n) < 0.3] = 0.0  # zero weights (already chosen centres) too
        if p.sum() == 0:
            p[0] = 1.0
        p /= p.sum()
        for size in (1, 2, 3, 5):
            assert np.array_equal(_draw(ours, p, size), numpys.choice(n, size=size, p=p))
        assert ours.random() == numpys.random()
