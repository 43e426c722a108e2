"""A Gaussian mixture in voxel units: its likelihood, its BIC, and the algebra of our EM (paper §III-D).

``BIC = k ln(n) - 2 ln L`` with ``k = 10 T - 1`` (3 T means, 6 T covariance entries, T - 1 free
weights), the same value as ``sklearn.mixture.GaussianMixture.bic`` for the same parameters.

EM in :mod:`planner.bic_search` works on quadratic features: the log-densities of all components
are one product ``features(x) @ weight_matrix(...).T`` of the (N, 10) features
``[x^2, y^2, z^2, xy, xz, yz, x, y, z, 1]`` with a (T, 10) matrix, and an M-step turns the
per-component sums of those features back into masses, means and covariances (``moments``).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from planner import small_linalg

_LOG2PI = float(np.log(2.0 * np.pi))
_EPS10 = 10.0 * float(np.finfo(np.float64).eps)  # sklearn's floor on component mass
_SYM = np.array([0, 3, 4, 3, 1, 5, 4, 5, 2])  # feature index of each entry of x x^T
_DIAG = np.array([0, 4, 8])  # flat indices of P_00, P_11, P_22 in a 3x3 matrix
_OFF = np.array([1, 2, 5])  # flat indices of P_01, P_02, P_12
_REG_EYE: dict[float, NDArray[np.float64]] = {}


@dataclass(frozen=True, eq=False)
class Mixture:
    """A Gaussian mixture in voxel units. weights (T,), means (T, 3), covariances (T, 3, 3)."""

    weights: NDArray[np.float64]
    means: NDArray[np.float64]
    covariances: NDArray[np.float64]

    @property
    def n_components(self) -> int:
        return int(self.weights.shape[0])


@dataclass(frozen=True, eq=False)
class Selection:
    """Result of model selection: the chosen mixture (voxel units), its exact BIC and all evaluated BICs."""

    mixture: Mixture
    bic: float
    evaluated: dict[int, float]


def n_parameters(t: int) -> int:
    """Free parameters of a T-component full-covariance GMM in 3-D: 3T + 6T + (T - 1)."""
    return 10 * t - 1


def log_likelihood(points_vox: NDArray[np.float64], mixture: Mixture) -> float:
    """sum_i log p(x_i), computed like scikit-learn (Cholesky of the precision). points_vox: (N, 3)."""
    chol = np.transpose(np.linalg.inv(np.linalg.cholesky(mixture.covariances)), (0, 2, 1))  # U U^T = cov^-1
    log_det = np.log(np.diagonal(chol, axis1=1, axis2=2)).sum(axis=1)
    y = np.matmul(points_vox[None], chol) - np.matmul(mixture.means[:, None, :], chol)  # (T, N, 3)
    lp = -0.5 * (3 * _LOG2PI + (y * y).sum(axis=2)) + (log_det + np.log(mixture.weights))[:, None]
    m = lp.max(axis=0)
    return float((m + np.log(np.exp(lp - m).sum(axis=0))).sum())


def bic_value(points_vox: NDArray[np.float64], mixture: Mixture) -> float:
    """-2 ln L + (10 T - 1) ln n, equal to ``GaussianMixture.bic`` with the same parameters."""
    n = points_vox.shape[0]
    return -2.0 * log_likelihood(points_vox, mixture) + n_parameters(mixture.n_components) * np.log(n)


def assign(points_vox: NDArray[np.float64], mixture: Mixture) -> NDArray[np.int64]:
    """(N,) int64 index of each point's most probable component (max of log w_t + log N_t)."""
    offset = points_vox.mean(axis=0)
    W = weight_matrix(mixture.weights, mixture.means - offset, mixture.covariances)
    return np.argmax(W @ features(points_vox - offset).T, axis=0).astype(np.int64)


def features(x: NDArray[np.float64]) -> NDArray[np.float64]:
    """(N, 10) quadratic features [x^2, y^2, z^2, xy, xz, yz, x, y, z, 1] of points (N, 3)."""
    a, b, c = x.T
    return np.column_stack([a * a, b * b, c * c, a * b, a * c, b * c, a, b, c, np.ones(len(x))])


def weight_matrix(w: NDArray, mu: NDArray, cov: NDArray) -> NDArray[np.float64]:
    """(T, 10) W with features(x) @ W.T = log w_t + log N(x | mu_t, cov_t)."""
    P = small_linalg.inv(cov)
    log_det = small_linalg.logdet(cov)
    Pm = np.einsum("tij,tj->ti", P, mu)
    W = np.empty((len(w), 10))
    P9 = P.reshape(-1, 9)
    np.multiply(P9[:, _DIAG], -0.5, out=W[:, 0:3])  # the squares' weights: -P_ii / 2
    np.negative(P9[:, _OFF], out=W[:, 3:6])  # the cross terms': -P_ij (i < j; P symmetric)
    W[:, 6:9] = Pm
    W[:, 9] = np.log(w) - 0.5 * (3 * _LOG2PI + log_det + np.einsum("ti,ti->t", mu, Pm))
    return W


def moments(S: NDArray[np.float64], reg: float) -> tuple[NDArray, NDArray, NDArray]:
    """Masses (T,), means (T, 3), covariances (T, 3, 3) from per-component feature sums S (T, 10)."""
    nk = S[:, 9] + _EPS10
    mu = S[:, 6:9] / nk[:, None]
    cov = S[:, _SYM].reshape(-1, 3, 3) / nk[:, None, None] - mu[:, :, None] * mu[:, None, :]
    cov += _identity_times(reg)
    return nk, mu, cov


def _identity_times(reg: float) -> NDArray[np.float64]:
    """``reg * np.eye(3)``, kept per value (EM adds it thousands of times a plan)."""
    out = _REG_EYE.get(reg)
    if out is None:
        out = reg * np.eye(3)
        out.flags.writeable = False
        if len(_REG_EYE) < 64:
            _REG_EYE[reg] = out
    return out
