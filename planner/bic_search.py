"""The fast BIC model selection over T for one voxel set (paper §III-D, ``cluster.search = "fast"``).

EM is our own numpy code: the log-densities of all components are one product of quadratic
features ``[x^2, y^2, z^2, xy, xz, yz, x, y, z, 1]`` with a (T, 10) matrix (``planner.mixture``), in
float32; M-steps are float64, and the models within ``_EXACT_BAND`` of the best get exact float64
BICs (scikit-learn's formula), the chosen one being the smallest of those. New models come from
evaluated neighbours: a split halves the components whose points a local two-Gaussian EM explains
best (moment-preserving, along the major axis); a merge joins the pairs with the smallest Runnalls
KL bound.

- Cold: one Gaussian split up to ``t_lo``, then T grows by ~1.5x per step until the BIC is far
  above the best.
- Warm (``warm`` = the previous iteration's mixture, what ``EllipsoidFitter`` keeps): EM from it,
  then steps of 1, 2, 4, ... outwards while the BIC drops.
- Then both bisect towards clearly worse evaluated neighbours, and polish: T - 1 and T + 1 from the
  best model, a split-and-merge move at T and seeded k-means restarts (several at T - 1 and T for
  small sets, one at T + 1 otherwise), walking on while that helps.

BIC drops smaller than ``_MIN_GAIN`` per point (EM noise at tol) do not steer the search. Models
with T outside ``[t_lo, t_hi]`` (EM can lose a component) only guide it: they are never chosen or
reported.

Used through :func:`planner.clustering.select_mixture`, which picks the search and limits BLAS to
one thread.
"""

from __future__ import annotations

import numpy as np
from numpy.typing import NDArray

from planner import small_linalg
from planner.config import ClusterConfig
from planner.mixture import Mixture, Selection, bic_value, features, moments, n_parameters, weight_matrix

_GROW = 1.5  # cold search: T grows by this factor per coarse step
_FLAT = 0.01  # refine: no bisection towards a neighbour within this BIC per point of the best
_MIN_GAIN = 0.005  # per point: smaller BIC drops are EM noise (tol) and do not steer the search
_WARM_TOL = 0.5  # warm start: the previous model is refitted to this fraction of tol
_EXACT_BAND = 1e-3  # models within this BIC per point of the best get an exact float64 BIC
_RESTART_ITERS = 100  # EM iterations for a k-means restart (a slow one would not win anyway)
_RESTARTS = 3  # k-means restarts (seeds) per T in the polish of a small set
_SMALL_WORK = 8_000  # n * T at most for a small set (the dragon's first view: 264 voxels, T = 5)
_FAR = 0.5  # cold search: stop growing once the BIC is this much per point above the best


class FastSearch:
    """Warm-started split/merge search over T on one point set (centred voxel units inside)."""

    def __init__(self, x: NDArray[np.float64], config: ClusterConfig, t_lo: int, t_hi: int) -> None:
        self.cfg, self.t_lo, self.t_hi, self.n = config, t_lo, t_hi, x.shape[0]
        self.offset = x.mean(axis=0)
        self.x = x - self.offset
        self.F = features(self.x)
        self.FT32 = np.ascontiguousarray(self.F.T, dtype=np.float32)
        self.models: dict[int, tuple[float, Mixture]] = {}
        self.gains: dict[int, tuple[Mixture, NDArray[np.float64]]] = {}
        self.steps: dict[tuple[int, int], tuple[Mixture, tuple[Mixture, float]]] = {}

    def run(self, warm: Mixture | None) -> Selection:
        """Search, then return the best model with its exact BIC."""
        if warm is None or warm.n_components == 0:
            self._cold()
        else:
            self._warm(Mixture(warm.weights, warm.means - self.offset, warm.covariances))
        self._refine()
        self._polish()
        # Search BICs come from float32 log-densities (error <~ 1e-4 per point): recompute every model near
        # the best exactly (float64, scikit-learn's formula) and choose among those.
        # EM can lose components (a step may land below t_lo): such models guide the search but are never
        # chosen or reported while some model with T in [t_lo, t_hi] exists.
        models = {k: v for k, v in self.models.items() if self.t_lo <= k <= self.t_hi} or self.models
        evaluated = {k: v[0] for k, v in models.items()}
        best = min(evaluated.values())
        exact = {k: bic_value(self.x, m) for k, (b, m) in models.items() if b <= best + _EXACT_BAND * self.n}
        evaluated.update(exact)
        t = min(exact, key=lambda k: exact[k])
        mix = self.models[t][1]
        return Selection(Mixture(mix.weights, mix.means + self.offset, mix.covariances), exact[t], evaluated)

    # -- search strategies
    def _cold(self) -> None:
        t = self._record(self._em(self._resize(self._m_step(np.ones((1, self.n), np.float32)), self.t_lo)))
        while t < self.t_hi:
            t_next = self._record(self._step(t, min(self.t_hi, max(t + 1, round(t * _GROW)))))
            if t_next <= t:  # components died: nothing larger to find here
                break
            t = t_next
            if self.models[t][0] > self._best()[1] + _FAR * self.n:  # far past the minimum
                break

    def _warm(self, warm: Mixture) -> None:
        t0 = min(max(warm.n_components, self.t_lo), self.t_hi)
        t0 = self._record(self._em(self._resize(warm, t0), _WARM_TOL * self.cfg.tol))  # a well-settled base
        for direction in (1, -1):
            t, step = t0, 1
            while True:
                t_next = min(max(t + direction * step, self.t_lo), self.t_hi)
                if t_next == t or t_next in self.models:
                    break
                t_next = self._record(self._step(t, t_next))
                if t_next == t or self.models[t_next][0] > self.models[t][0] - _MIN_GAIN * self.n:
                    break
                t, step = t_next, 2 * step

    def _refine(self) -> None:
        """Bisect between the best T and its evaluated neighbours until they are adjacent (or flat)."""
        tried: set[int] = set()
        while True:
            best_t, best_bic = self._best()
            ts = sorted(self.models)
            i = ts.index(best_t)
            # Bisect towards evaluated neighbours that are not adjacent and clearly worse (a flat side: the
            # T between are about as good as both ends, within the fidelity budget).
            sides = [
                ts[j]
                for j in (i - 1, i + 1)
                if 0 <= j < len(ts) and abs(ts[j] - best_t) > 1 and self.models[ts[j]][0] - best_bic > _FLAT * self.n
            ]
            if not sides:
                return
            far = max(sides, key=lambda s: (abs(s - best_t), -self.models[s][0]))
            mid = (far + best_t) // 2
            if mid in tried:  # components died on the way: give up on this gap
                return
            tried.add(mid)
            lo, hi = min(far, best_t), max(far, best_t)
            self._record(self._step(lo if mid - lo <= hi - mid else hi, mid))

    def _polish(self) -> None:
        """From the best model try T - 1 (merge), T + 1 (split), a split-and-merge at T (Ueda et al. 2000) and
        k-means restarts (they escape local optima); then walk on in the direction that improved."""
        best_t, best_bic = self._best()
        for t_to in (best_t - 1, best_t + 1):
            if self.t_lo <= t_to <= self.t_hi:
                self._record(self._step(best_t, t_to))
        if best_t >= 2:
            mix = self.models[best_t][1]
            g = int(np.argmax(self._gains(mix)))
            self._record(self._em(_merge(_split(mix, np.array([g])), 1, forbid=(g, best_t))))
        # independent basins from scikit-learn's own start (k-means): splits and merges can all mislead.
        # Small sets get several full restarts round T (cheap, and one bad basin costs many BIC units per
        # voxel there); large ones one quick restart at T + 1.
        if self.n * best_t <= _SMALL_WORK:
            for t_k in (best_t - 1, best_t):
                if self.t_lo <= t_k <= self.t_hi:
                    for restart in range(_RESTARTS):
                        self._record(self._em(self._kmeans(t_k, restart=restart)))
        elif best_t < self.t_hi:
            self._record(self._em(self._kmeans(best_t + 1, iters=10, greedy=False), max_iter=_RESTART_ITERS))
        t, bic = self._best()
        step, margin = int(np.sign(t - best_t)), 0.0  # the first step after a move needs no margin
        while step and bic < best_bic - margin and self.t_lo <= t + step <= self.t_hi:
            best_bic, margin = bic, _MIN_GAIN * self.n
            self._record(self._step(t, t + step))
            t, bic = self._best()

    # -- helpers
    def _kmeans(self, t: int, iters: int = 100, restart: int = 0, greedy: bool = True) -> Mixture:
        """Seeded k-means++ and Lloyd iterations (to convergence, at most ``iters``), as a mixture:
        scikit-learn's default initialisation of EM (greedy: ``2 + ln t`` candidate centres per pick,
        the best one kept)."""
        rng = np.random.default_rng((self.cfg.seed, restart))
        x = self.x
        trials = 2 + int(np.log(t)) if greedy else 1
        centres = [x[rng.integers(self.n)]]
        d2 = ((x - centres[0]) ** 2).sum(axis=1)
        for _ in range(1, t):
            picks = _draw(rng, d2 / d2.sum(), trials)
            cand = np.minimum(d2[None, :], ((x[None, :, :] - x[picks][:, None, :]) ** 2).sum(axis=2))
            best = int(np.argmin(cand.sum(axis=1)))
            centres.append(x[picks[best]])
            d2 = cand[best]
        C = np.array(centres)
        lab = np.full(self.n, -1)
        for _ in range(iters):
            new = np.argmin((C * C).sum(axis=1)[:, None] - 2.0 * C @ x.T, axis=0)
            if np.array_equal(new, lab):
                break
            lab = new
            cnt = np.bincount(lab, minlength=t)
            sums = np.stack([np.bincount(lab, weights=x[:, k], minlength=t) for k in range(3)], axis=1)
            C = np.where(cnt[:, None] > 0, sums / np.maximum(cnt, 1)[:, None], C)
        R = np.zeros((t, self.n))
        R[lab, np.arange(self.n)] = 1.0
        return self._m_step(R)

    def _best(self) -> tuple[int, float]:
        t = min(self.models, key=lambda k: self.models[k][0])
        return t, self.models[t][0]

    def _record(self, fitted: tuple[Mixture, float]) -> int:
        """Keep ``fitted`` if it is the best model with its T so far; returns T."""
        mix, ll = fitted
        t = mix.n_components
        bic = -2.0 * ll + n_parameters(t) * np.log(self.n)
        if t not in self.models or bic < self.models[t][0]:
            self.models[t] = (bic, mix)
        return t

    def _step(self, t_from: int, t_to: int) -> tuple[Mixture, float]:
        """EM on the current best T = t_from model resized to t_to (memoised per base model)."""
        base = self.models[t_from][1]
        key = (id(base), t_to)
        if key not in self.steps:
            self.steps[key] = (base, self._em(self._resize(base, t_to)))  # base kept alive: ids stay unique
        return self.steps[key][1]

    def _e_step(self, mix: Mixture) -> tuple[NDArray[np.float32], float]:
        """Responsibilities (T, N) float32 and the log-likelihood of ``mix``."""
        L = weight_matrix(mix.weights, mix.means, mix.covariances).astype(np.float32) @ self.FT32
        m = L.max(axis=0)
        L -= m
        np.exp(L, out=L)
        s = L.sum(axis=0)
        ll = float(np.log(s).sum(dtype=np.float64) + m.sum(dtype=np.float64))
        L *= 1.0 / s
        return L, ll

    def _m_step(self, R: NDArray) -> Mixture:
        """Mixture from responsibilities R (T, N); components with less than one point of mass are dropped."""
        nk, mu, cov = moments(R.astype(np.float64) @ self.F, self.cfg.reg_covar_voxels)
        keep = nk >= 1.0
        if keep.all() or not keep.any():  # none dead (or all: keep them all)
            return Mixture(nk / nk.sum(), mu, cov)
        return Mixture(nk[keep] / nk[keep].sum(), mu[keep], cov[keep])

    def _em(self, mix: Mixture, tol: float | None = None, max_iter: int | None = None) -> tuple[Mixture, float]:
        """EM until the mean log-likelihood changes by < tol; returns the mixture and its log-likelihood."""
        prev, tol = -np.inf, self.cfg.tol if tol is None else tol
        for _ in range(min(self.cfg.max_iter, max_iter or self.cfg.max_iter)):
            R, ll = self._e_step(mix)
            if abs(ll / self.n - prev) < tol:
                return mix, ll
            prev = ll / self.n
            mix = self._m_step(R)
        return mix, self._e_step(mix)[1]

    def _resize(self, mix: Mixture, t_to: int) -> Mixture:
        """Split (by local gain) or merge (by Runnalls bound) components until there are ``t_to``."""
        while mix.n_components < t_to:
            k = min(t_to - mix.n_components, mix.n_components)
            mix = _split(mix, np.argsort(-self._gains(mix))[:k])
        while mix.n_components > t_to:
            merged = _merge(mix, mix.n_components - t_to)
            if merged.n_components == mix.n_components:
                break
            mix = merged
        return mix

    def _gains(self, mix: Mixture) -> NDArray[np.float64]:
        """Memoised ``_split_gains``."""
        if id(mix) not in self.gains:
            self.gains[id(mix)] = (mix, self._split_gains(mix))  # keeps mix alive, so ids stay unique
        return self.gains[id(mix)][1]

    def _split_gains(self, mix: Mixture, iters: int = 3) -> NDArray[np.float64]:
        """(T,) log-likelihood gain of a local two-Gaussian EM on each component's hard-assigned points."""
        t = mix.n_components
        Lp = weight_matrix(np.ones(t), mix.means, mix.covariances) @ self.F.T
        lab = np.argmax(Lp + np.log(mix.weights)[:, None], axis=0)
        order = np.argsort(lab, kind="stable")
        lab_s, F_s = lab[order], self.F[order]
        parent = Lp[lab_s, order]
        present = np.flatnonzero(np.bincount(lab_s, minlength=t))
        starts = np.searchsorted(lab_s, present)
        child = _split(Mixture(np.ones(t), mix.means, mix.covariances), np.arange(t))  # halves k and k + t
        cw, cmu, ccov = np.full(2 * t, 0.5), child.means, child.covariances
        ll = parent
        for _ in range(iters):
            W = weight_matrix(cw, cmu, ccov)
            L2 = np.stack([np.einsum("ni,ni->n", F_s, W[lab_s]), np.einsum("ni,ni->n", F_s, W[lab_s + t])])
            m = L2.max(axis=0)
            E = np.exp(L2 - m)
            s = E.sum(axis=0)
            ll = m + np.log(s)
            E /= s
            S = np.zeros((2, t, 10))
            S[:, present] = np.add.reduceat(E[:, :, None] * F_s[None], starts, axis=1)
            nk, cmu, ccov = moments(S.reshape(2 * t, 10), self.cfg.reg_covar_voxels)
            dead = nk < 1.0  # an empty half: restart it from its parent
            cmu[dead], ccov[dead] = np.tile(mix.means, (2, 1))[dead], np.tile(mix.covariances, (2, 1, 1))[dead]
            pair = nk[:t] + nk[t:]
            cw = np.concatenate([nk[:t] / pair, nk[t:] / pair])
        return np.bincount(lab_s, weights=ll - parent, minlength=t).astype(np.float64)


def _draw(rng: np.random.Generator, p: NDArray[np.float64], size: int) -> NDArray[np.int64]:
    """(size,) indices drawn with probabilities p (N,) (sum 1), with replacement: ``rng.choice(N, size, p=p)``'s
    draws (the same inverse-CDF rule on the same uniforms), without its argument checks (a fifth of a k-means)."""
    cdf = p.cumsum()
    cdf /= cdf[-1]
    return cdf.searchsorted(rng.random(size), side="right").astype(np.int64, copy=False)


def _split(mix: Mixture, idx: NDArray[np.int64]) -> Mixture:
    """Split components ``idx`` along their major axes (moment preserving); second halves are appended."""
    lam, V = np.linalg.eigh(mix.covariances[idx])
    v, var = V[:, :, -1], lam[:, -1]
    d = np.sqrt(2.0 / np.pi * var)[:, None] * v
    c = mix.covariances[idx] - (2.0 / np.pi) * var[:, None, None] * (v[:, :, None] * v[:, None, :])
    w, mu, cov = mix.weights.copy(), mix.means.copy(), mix.covariances.copy()
    w[idx] *= 0.5
    mu[idx] += d
    cov[idx] = c
    return Mixture(np.concatenate([w, w[idx]]), np.concatenate([mu, mix.means[idx] - d]), np.concatenate([cov, c]))


def _merge(mix: Mixture, count: int, forbid: tuple[int, int] | None = None) -> Mixture:
    """Merge ``count`` disjoint pairs with the smallest Runnalls bound (moment preserving), never ``forbid``."""
    w, mu, cov = mix.weights.copy(), mix.means.copy(), mix.covariances.copy()
    t = len(w)
    ld = small_linalg.logdet(cov)
    ws = w[:, None] + w[None, :]
    a = (w[:, None] / ws)[..., None]
    mm = a * mu[:, None, :] + (1 - a) * mu[None, :, :]
    di, dj = mu[:, None, :] - mm, mu[None, :, :] - mm
    C = a[..., None] * (cov[:, None] + di[..., :, None] * di[..., None, :]) + (1 - a[..., None]) * (
        cov[None, :] + dj[..., :, None] * dj[..., None, :]
    )
    cost = 0.5 * (ws * small_linalg.logdet(C) - w[:, None] * ld[:, None] - w[None, :] * ld[None, :])
    cost[np.tril_indices(t)] = np.inf
    if forbid is not None:
        cost[min(forbid), max(forbid)] = np.inf
    used: set[int] = set()
    for flat in np.argsort(cost, axis=None)[: t * (t - 1) // 2]:  # finite costs first
        i, j = divmod(int(flat), t)
        if len(used) < 2 * count and np.isfinite(cost[i, j]) and i not in used and j not in used:
            used.update((i, j))
            w[i], mu[i], cov[i] = ws[i, j], mm[i, j], C[i, j]
            w[j] = -1.0  # marks j as merged away
    keep = w >= 0
    return Mixture(w[keep], mu[keep], cov[keep])
