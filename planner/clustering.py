"""Gaussian-mixture clustering of voxel centres with BIC model selection (paper §III-D).

One kind of voxel (occupied or frontier) is clustered at a time by a full-covariance GMM with T
components, T chosen by the smallest ``BIC = k ln(n) - 2 ln L``, ``k = 10 T - 1`` (3 T means, 6 T
covariance entries, T - 1 free weights; the same count as ``sklearn.mixture.GaussianMixture.bic``).

Units. Points are divided by the voxel edge (voxel units) and ``reg_covar = config.reg_covar_voxels``
(1/12, the variance of a point uniform inside one voxel) is added to every covariance diagonal.
Voxel centres lie on a lattice: a cluster on a plane or a line has zero variance across it, and
without the floor its likelihood (hence its BIC) grows without bound as the Gaussian collapses.
With the floor every Gaussian is at least one voxel "thick", and the BIC does not depend on
the voxel size chosen in metres.

Few points. With n points T is capped at ``t_hi = max(1, n // min_points_per_component)``
(never more than ``t_max``), and ``t_lo = min(t_min, t_hi)``; n == 0 gives no model (T = 0).

Search: ``search="fast"`` (default) is the warm-started split/merge search of
:mod:`planner.bic_search`; ``search="exhaustive"`` fits every T in ``[t_lo, t_hi]`` with scikit-learn
(the reference, and what ``bic_sweep`` measures the fast search against). The mixture, its BIC and the
EM algebra are in :mod:`planner.mixture`.
"""

from __future__ import annotations

from collections.abc import Callable, Iterable, Mapping
from contextlib import AbstractContextManager

import numpy as np
from numpy.typing import NDArray

from planner.bic_search import FastSearch
from planner.config import ClusterConfig
from planner.mixture import Mixture, Selection
from planner.mvee import checked_points


def t_range(n: int, config: ClusterConfig) -> tuple[int, int]:
    """(t_lo, t_hi) for n points (the few-points rule of the module docstring); (0, 0) for n == 0."""
    if n <= 0:
        return 0, 0
    t_hi = min(config.t_max, max(1, n // config.min_points_per_component))
    return min(config.t_min, t_hi), t_hi


def bic_sweep(
    points_world: NDArray[np.float64], t_values: Iterable[int], config: ClusterConfig, resolution: float
) -> dict[int, float]:
    """Reference: scikit-learn ``GaussianMixture`` (full, reg_covar in voxel units, seeded) BIC per T."""
    x = checked_points("points_world", points_world, 1) / _checked_resolution(resolution)
    return {t: bic for t, (bic, _) in _sklearn_fits(x, t_values, config).items()}


def bic_gap(chosen_bic: float, sweep: Mapping[int, float], n_points: int) -> float:
    """(chosen_bic - min(sweep)) / n_points: how much worse than the exhaustive reference, per voxel."""
    if not sweep or n_points <= 0:
        raise ValueError("bic_gap: need a non-empty sweep and n_points > 0")
    return (chosen_bic - min(sweep.values())) / n_points


def select_mixture(
    points_vox: NDArray[np.float64],
    config: ClusterConfig,
    warm: Mixture | None = None,
    progress: Callable[[int, int], None] | None = None,
) -> Selection:
    """Choose T and fit the GMM; ``warm`` (voxel units) seeds the fast search. points_vox: (N, 3), N >= 1.

    progress: called with ``(done, total)`` values of T as the exhaustive search fits them; the fast search (a
    few tens of milliseconds) reports only its end."""
    n = points_vox.shape[0]
    t_lo, t_hi = t_range(n, config)
    if config.search == "exhaustive":
        fits = _sklearn_fits(points_vox, range(t_lo, t_hi + 1), config, progress)
        best = min(fits, key=lambda t: fits[t][0])
        return Selection(fits[best][1], fits[best][0], {t: b for t, (b, _) in fits.items()})
    with single_thread_blas():  # tiny GEMMs: thread hand-offs cost more than they save (3-10x slower)
        selection = FastSearch(points_vox, config, t_lo, t_hi).run(warm)
    if progress is not None:
        progress(1, 1)
    return selection


_controller: list = []


def single_thread_blas() -> AbstractContextManager:
    """Limit BLAS to one thread (a cached threadpoolctl controller: ~10 us instead of ~0.6 ms)."""
    if not _controller:
        from threadpoolctl import ThreadpoolController

        _controller.append(ThreadpoolController())
    return _controller[0].limit(limits=1, user_api="blas")


def fit_fixed_t(points_vox: NDArray[np.float64], t: int, config: ClusterConfig) -> tuple[float, Mixture]:
    """(BIC, mixture) of scikit-learn's seeded EM with exactly ``t`` components. points_vox: (N, 3), N >= t."""
    return _sklearn_fits(points_vox, [t], config)[t]


def _checked_resolution(resolution: float) -> float:
    if not np.isfinite(resolution) or resolution <= 0:
        raise ValueError(f"resolution: must be a finite number > 0, got {resolution!r}")
    return float(resolution)


def _sklearn_fits(
    x: NDArray[np.float64],
    t_values: Iterable[int],
    cfg: ClusterConfig,
    progress: Callable[[int, int], None] | None = None,
) -> dict[int, tuple[float, Mixture]]:
    from sklearn.mixture import GaussianMixture

    out: dict[int, tuple[float, Mixture]] = {}
    ts = sorted(set(t_values))
    for i, t in enumerate(ts):
        if progress is not None:
            progress(i, len(ts))
        kw = {"reg_covar": cfg.reg_covar_voxels, "max_iter": cfg.max_iter, "tol": cfg.tol, "random_state": cfg.seed}
        gm = GaussianMixture(t, covariance_type="full", **kw).fit(x)
        out[t] = (
            float(gm.bic(x)),
            Mixture(np.asarray(gm.weights_), np.asarray(gm.means_), np.asarray(gm.covariances_)),
        )
    if progress is not None:
        progress(len(ts), len(ts))
    return out
