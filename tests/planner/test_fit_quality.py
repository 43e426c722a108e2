"""The fit's labels and weights (what the clusters layer colours by), the fit at a fixed T, fill ratios and the
worst-filled-first order of the Fit panel."""

from __future__ import annotations

import math

import numpy as np
import pytest

from planner import Ellipsoid
from planner.config import ClusterConfig
from planner.ellipsoids import EllipsoidFitter, dense, fit_at_t
from planner.fit_quality import (
    LOW_FILL,
    ellipsoid_label,
    ellipsoid_volume,
    fill_ratio,
    fit_rows,
    worst_filled_first,
)
from planner.mixture import assign

RES = 0.01


def _blobs() -> np.ndarray:
    """Three separated balls of voxel centres (radii 3, 2, 2 voxels), world metres."""
    g = np.stack(np.meshgrid(*[np.arange(-4, 5)] * 3, indexing="ij"), -1).reshape(-1, 3)
    r = np.linalg.norm(g, axis=1)
    parts = [g[r <= 3] + [0, 0, 0], g[r <= 2] + [12, 0, 0], g[r <= 2] + [0, 12, 0]]
    return (np.vstack(parts) + 0.5) * RES


def _inside(e: Ellipsoid, p: np.ndarray) -> np.ndarray:
    y = p - e.center
    return np.einsum("ni,ij,nj->n", y, e.shape_matrix, y) <= 1 + 1e-9


def test_labels_name_each_voxel_s_ellipsoid_and_the_weights_are_the_mixture_s() -> None:
    pts = _blobs()
    fitter = EllipsoidFitter(ClusterConfig(t_min=1, t_max=6), RES, "occupied")
    ellipsoids, fit = fitter.fit(pts)
    assert fit.labels is not None and fit.labels.dtype == np.int32 and len(fit.labels) == len(pts)
    assert len(ellipsoids) == 3
    # the labels are the GMM's assignment, renumbered to the ellipsoids' order
    raw = assign(pts / RES, fitter.mixture)  # type: ignore[arg-type]
    comps = np.unique(raw)
    assert np.array_equal(comps[fit.labels], raw)
    for k, e in enumerate(ellipsoids):
        mine = pts[fit.labels == k]
        assert len(mine) == e.n_points and np.all(_inside(e, mine))
        assert e.gmm_weight == pytest.approx(fitter.mixture.weights[comps[k]])  # type: ignore[union-attr]
    # the three balls are the three clusters: each ball's voxels share one label, the balls' labels differ
    g = np.stack(np.meshgrid(*[np.arange(-4, 5)] * 3, indexing="ij"), -1).reshape(-1, 3)
    r = np.linalg.norm(g, axis=1)
    n0, n1 = int(np.sum(r <= 3)), int(np.sum(r <= 2))
    parts = [fit.labels[:n0], fit.labels[n0 : n0 + n1], fit.labels[n0 + n1 :]]
    assert [len(set(p.tolist())) for p in parts] == [1, 1, 1]
    assert len({int(p[0]) for p in parts}) == 3
    assert sum(e.gmm_weight for e in ellipsoids) == pytest.approx(1.0)  # type: ignore[misc]


def test_dense_renumbers_the_components_that_occur() -> None:
    assert dense(np.array([5, 2, 5, 9, 2])).tolist() == [1, 0, 1, 2, 0]
    assert dense(np.array([0, 0])).tolist() == [0, 0]


def test_a_fit_at_fixed_t_has_t_clusters_and_leaves_the_warm_start_alone() -> None:
    pts = _blobs()
    cfg = ClusterConfig(t_min=1, t_max=6)
    fitter = EllipsoidFitter(cfg, RES, "frontier")
    fitter.fit(pts)
    warm = fitter.mixture
    ellipsoids, fit = fitter.fit_at(pts, 5)
    assert fitter.mixture is warm  # the planner's next fit starts where it would have
    assert fit.t_chosen == 5 and len(ellipsoids) == 5 and fit.bic[0][0] == 5
    assert fit.labels is not None and sorted(set(fit.labels.tolist())) == list(range(5))
    for k, e in enumerate(ellipsoids):
        assert e.kind == "frontier" and np.all(_inside(e, pts[fit.labels == k]))
    # the BIC is scikit-learn's at T=5: worse than the three-cluster model's on three balls
    three = fit_at_t(pts, cfg, RES, "frontier", 3)[1]
    assert three.bic[0][1] < fit.bic[0][1]
    for bad in (0, len(pts) + 1, 2.5, True):
        with pytest.raises(ValueError, match="t: must be an integer"):
            fitter.fit_at(pts, bad)  # type: ignore[arg-type]


def test_fill_ratio_is_voxel_volume_over_ellipsoid_volume() -> None:
    e = Ellipsoid(np.zeros(3), np.array([0.03, 0.02, 0.01]), np.eye(3), "occupied", n_points=10)
    volume = 4 / 3 * math.pi * 0.03 * 0.02 * 0.01
    assert ellipsoid_volume(e) == pytest.approx(volume)
    assert fill_ratio(e, 0.01) == pytest.approx(10 * 1e-6 / volume)  # 10 cm^3 of voxels in 25.1 cm^3: 0.398
    assert fill_ratio(e, 0.01) == pytest.approx(0.3979, abs=1e-4)
    with pytest.raises(ValueError, match="resolution"):
        fill_ratio(e, 0.0)


def test_rows_name_ellipsoids_like_the_inspector_and_put_the_worst_filled_first() -> None:
    def ball(kind: str, radius: float, n: int) -> Ellipsoid:
        return Ellipsoid(np.zeros(3), np.full(3, radius), np.eye(3), kind, n_points=n, gmm_weight=0.5)  # type: ignore[arg-type]

    # fills: O0 0.24, O1 0.03 (flagged), F0 0.0060 (flagged), F1 0.24
    ells = [ball("occupied", 0.01, 1), ball("occupied", 0.02, 1), ball("frontier", 0.05, 3), ball("frontier", 0.01, 1)]
    rows = fit_rows(ells, 0.01)
    assert [r.label for r in rows] == ["O0", "O1", "F0", "F1"] and [r.plan_index for r in rows] == [0, 1, 2, 3]
    assert [ellipsoid_label("frontier", 7), ellipsoid_label("occupied", 0)] == ["F7", "O0"]
    assert rows[0].fill == pytest.approx(1e-6 / (4 / 3 * math.pi * 1e-6))
    assert [r.low_fill for r in rows] == [False, True, True, False]
    assert all(r.fill < LOW_FILL for r in rows if r.low_fill)
    assert [r.label for r in worst_filled_first(rows)] == ["O1", "O0", "F0", "F1"]
    assert rows[2].voxel_volume == pytest.approx(3e-6) and rows[2].weight == 0.5
