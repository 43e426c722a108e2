"""Minimum-volume enclosing ellipsoids (MVEE) of 3-D point sets (paper §III-D).

The paper uses Gärtner's exact algorithm from CGAL; we solve the same convex problem to a relative
tolerance with Khachiyan's algorithm plus Todd–Yildirim away steps ("WA-TY", Todd & Yildirim 2007,
the Wolfe-Atwood scheme): lift points to q_i = (p_i, 1), keep weights u on the simplex, and move
weight towards the point with the largest ``w_i = q_i^T X(u)^-1 q_i`` (X = sum u_i q_i q_i^T) or away
from the supported point with the smallest; stop when ``max w <= 4 (1 + tol)`` and
``min_{u_i > 0} w >= 4 (1 - tol)``. X^-1 and w get rank-one (Sherman–Morrison) updates, so an iteration
costs O(N) per set.

Optional warm-up: ``warmup`` multiplicative steps ``u_i <- u_i w_i / 4`` (Titterington's algorithm)
first; they move all weights at once and bring the ellipsoid within ~1 % of the minimum volume in a
few dozen cheap steps, where WA-TY's single-point steps need hundreds. The weights of whichever stage
gives the smaller contained ellipsoid are kept.

``mvee_batch`` solves many sets at once (padded, vectorised over sets). Results are finally scaled
so that every input point satisfies ``(x - c)^T A (x - c) <= 1``: containment is exact and the
farthest point lies on the surface; minimality holds to ``tol`` when WA-TY converged.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np
from numpy.typing import ArrayLike, NDArray

from planner import small_linalg

_D = 3
_N = _D + 1.0
_HULL_ABOVE = 20  # mvee(): reduce to convex-hull vertices above this many points
_REFRESH = 40  # recompute X^-1 and w exactly every this many WA-TY iterations (rank-one drift)


def mvee(points: ArrayLike, tol: float = 1e-4, max_iter: int = 2000) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """MVEE of ``points`` (N, 3), N >= 4, not all on one plane.

    Returns center (3,) and A (3, 3) symmetric positive definite with (x - c)^T A (x - c) <= 1 for all points.
    """
    p = checked_points("points", points)
    if p.shape[0] < _D + 1:
        raise ValueError(f"points: need at least {_D + 1} points, got {p.shape[0]}")
    candidates = p
    if p.shape[0] > _HULL_ABOVE and not _flat(p[None] - p.mean(axis=0))[0]:
        from scipy.spatial import ConvexHull

        candidates = p[ConvexHull(p).vertices]
    centers, A, _ = solve([candidates], tol=tol, max_iter=max_iter, single=True)
    return centers[0], _scale_to_contain(p - centers[0], A[0])


def mvee_batch(
    point_sets: Sequence[ArrayLike], tol: float = 1e-4, max_iter: int = 2000, warmup: int = 0
) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """MVEEs of S affinely spanning point sets (each (N_s, 3), N_s >= 4) at once.

    Returns centers (S, 3) and A (S, 3, 3); each set's points satisfy (x - c)^T A (x - c) <= 1.
    """
    sets = [checked_points(f"point_sets[{i}]", s) for i, s in enumerate(point_sets)]
    centers, A, _ = solve(sets, tol=tol, max_iter=max_iter, warmup=warmup)
    return centers, A


def solve(
    sets: Sequence[NDArray[np.float64]],
    weights: Sequence[NDArray[np.float64]] | None = None,
    tol: float = 1e-4,
    max_iter: int = 2000,
    warmup: int = 0,
    single: bool = False,
) -> tuple[NDArray[np.float64], NDArray[np.float64], list[NDArray[np.float64]]]:
    """``mvee_batch`` on checked (N_s, 3) float64 sets, optionally from initial ``weights`` (each (N_s,) >= 0).

    Returns centers (S, 3), A (S, 3, 3) scaled to contain each set, and the final weights per set.
    ``single``: errors name the one set "points" (``mvee``) instead of "point_sets[i]".
    """
    if not np.isfinite(tol) or tol <= 0:
        raise ValueError(f"tol: must be a finite number > 0, got {tol!r}")
    if not sets:
        return np.zeros((0, _D)), np.zeros((0, _D, _D)), []
    counts = np.array([len(s) for s in sets])
    if counts.min() < _D + 1:
        raise ValueError(f"point_sets: every set needs >= {_D + 1} points, smallest has {counts.min()}")
    S, m = len(sets), int(counts.max())
    # Centre each set (conditioning) and pad with copies of its first point: duplicates change nothing,
    # and argmax takes the first of equal values, so padding never gains weight.
    mean = np.array([s.mean(axis=0) for s in sets])
    P = np.empty((S, m, _D))
    u = np.zeros((S, m))
    for i, s in enumerate(sets):
        P[i, : len(s)] = s - mean[i]
        P[i, len(s) :] = s[0] - mean[i]
        u0 = np.full(len(s), 1.0) if weights is None else np.maximum(weights[i], 0.0)
        u[i, : len(s)] = u0 / u0.sum()
    flat = _flat(P)
    if flat.any():
        name = "points" if single else f"point_sets[{int(np.argmax(flat))}]"
        raise ValueError(f"{name}: affinely degenerate (all on one plane or line); the MVEE would be flat")
    Q = np.concatenate([P, np.ones((S, m, 1))], axis=2)
    u = _wa_ty(Q, _multiplicative(Q, u, warmup), tol, max_iter)
    c = np.matmul(u[:, None, :], P)[:, 0]
    d = P - c[:, None, :]
    A = small_linalg.inv(np.matmul(np.transpose(d, (0, 2, 1)) * u[:, None, :], d))
    reach = np.einsum("smi,smi->sm", np.matmul(d, A), d).max(axis=1)
    A /= (reach * (1.0 + 1e-12))[:, None, None]
    return c + mean, A, [u[i, : counts[i]] for i in range(S)]


def _flat(P: NDArray) -> NDArray[np.bool_]:
    """(S,) True where the centred sets P (S, m, 3) do not span 3-D (relative singular value < 1e-9)."""
    sv = np.linalg.svd(P, compute_uv=False)
    return sv[:, -1] <= 1e-9 * np.maximum(sv[:, 0], 1e-300)


def _multiplicative(Q: NDArray, u: NDArray, steps: int) -> NDArray[np.float64]:
    """``steps`` Titterington updates u_i <- u_i w_i / 4 on lifted points Q (S, m, 4), weights u (S, m)."""
    QT = np.ascontiguousarray(np.transpose(Q, (0, 2, 1)))
    for _ in range(steps):
        Xinv = small_linalg.inv(np.matmul(QT * u[:, None, :], Q))
        u = u * np.einsum("smi,smi->sm", np.matmul(Q, Xinv), Q) / _N
    return u


def _wa_ty(Q: NDArray, u: NDArray, tol: float, max_iter: int) -> NDArray[np.float64]:
    """WA-TY iterations on lifted points Q (S, m, 4) from weights u (S, m); the better of start and end."""
    rows = np.arange(Q.shape[0])
    Xinv, w = _exact(Q, u)
    u_start, v_start = u.copy(), _contained_volume(Xinv, w)
    for it in range(max_iter):
        if it and it % _REFRESH == 0:
            Xinv, w = _exact(Q, u)
        j = np.argmax(w, axis=1)
        k = np.argmin(np.where(u > 0, w, np.inf), axis=1)
        wj, wk, uk = w[rows, j], w[rows, k], u[rows, k]
        up, down = wj / _N - 1.0, 1.0 - wk / _N
        active = np.maximum(up, down) > tol
        if not active.any():
            break
        toward = up >= down
        b_away = (_N - wk) / (_N * (wk - 1.0))
        b_drop = uk / (1.0 - uk)  # the away step that removes point k
        drop = ~toward & (b_away >= b_drop)
        b = np.where(toward, (wj - _N) / (_N * (wj - 1.0)), -np.minimum(b_away, b_drop)) * active
        i, wi = np.where(toward, j, k), np.where(toward, wj, wk)
        shrink = 1.0 - b
        u *= shrink[:, None]
        u[rows, i] += b
        dropped = drop & active
        u[rows[dropped], k[dropped]] = 0.0
        Xq = np.matmul(Xinv, Q[rows, i][:, :, None])  # (S, 4, 1)
        coef = b / (shrink + b * wi)
        Xinv = (Xinv - coef[:, None, None] * Xq * np.transpose(Xq, (0, 2, 1))) / shrink[:, None, None]
        g = np.matmul(Q, Xq)[:, :, 0]  # (S, m)
        w = (w - coef[:, None] * g * g) / shrink[:, None]
    worse = _contained_volume(*_exact(Q, u)) > v_start  # early WA-TY steps can enlarge the contained ellipsoid
    u[worse] = u_start[worse]
    return u


def _exact(Q: NDArray, u: NDArray) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """X(u)^-1 (S, 4, 4) and w (S, m) from scratch."""
    Xinv = small_linalg.inv(np.matmul(np.transpose(Q, (0, 2, 1)) * u[:, None, :], Q))
    return Xinv, np.einsum("smi,smi->sm", np.matmul(Q, Xinv), Q)


def _contained_volume(Xinv: NDArray, w: NDArray) -> NDArray[np.float64]:
    """(S,) volume (up to a constant) of the ellipsoid of the weights, scaled to contain every point.

    With X = [[cov + c c^T, c], [c^T, 1]]: det X = det cov and w_i - 1 = (p_i - c)^T cov^-1 (p_i - c).
    """
    return np.sqrt(np.maximum(w.max(axis=1) - 1.0, 0.0) ** _D / np.linalg.det(Xinv))


def _scale_to_contain(d: NDArray, A: NDArray) -> NDArray[np.float64]:
    """A scaled so the farthest of the offsets d (N, 3) lies on the surface."""
    A = 0.5 * (A + A.T)
    return A / (float(np.einsum("ni,ij,nj->n", d, A, d).max()) * (1.0 + 1e-12))


def checked_points(name: str, points: ArrayLike, min_rows: int = 0) -> NDArray[np.float64]:
    """``points`` as an (N, 3) finite float64 array, else ``ValueError`` naming ``name``."""
    try:
        p = np.asarray(points, dtype=np.float64)
    except (TypeError, ValueError) as exc:
        raise ValueError(f"{name}: cannot convert to a float64 array ({exc})") from None
    if p.ndim != 2 or p.shape[1] != _D:
        raise ValueError(f"{name}: expected shape (N, 3), got {p.shape}")
    if not np.all(np.isfinite(p)):
        raise ValueError(f"{name}: {int(np.count_nonzero(~np.isfinite(p)))} non-finite value(s) (NaN or inf)")
    if p.shape[0] < min_rows:
        raise ValueError(f"{name}: need at least {min_rows} points, got {p.shape[0]}")
    return p
