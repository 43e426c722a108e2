"""Voxels -> clusters -> ellipsoids (paper §III-D, "EllipsoidsFit" of Algorithm 1).

``EllipsoidFitter.fit`` clusters the voxel centres of one kind with a GMM whose number of components is
chosen by BIC (``planner.clustering``), assigns every voxel to its most probable component (empty
components are dropped) and encloses each cluster by a minimum-volume ellipsoid (``planner.mvee``).

Minimum thickness. The ellipsoid of a cluster encloses its voxel *cubes*, not only their centres: the
MVEE of the union of the cubes (the hull of centres ⊕ the 8 corner offsets ±res/2). It is never
degenerate: a single voxel gives the sphere of radius (√3/2)·res, a planar or collinear cluster an
ellipsoid at least one voxel thick (every semi-axis >= res/2), and every voxel centre is inside.

Speed. Candidate support points are the cube corners that are extreme along 64 fixed directions
(vertices of the cubes' hull); all clusters go through one batched solve (``planner.mvee.solve``:
``mvee_warmup`` multiplicative steps, then at most ``mvee_max_iter`` WA-TY iterations). Corners the
candidates missed (more than 1 % outside) are added and the affected clusters solved once more from
their weights. Finally each ellipsoid is scaled so that every corner of every voxel of its cluster is
inside: containment is exact; the volume is within a few per cent of the minimum (benchmarks/bench_fit.py).
A plan fits two kinds: ``EllipsoidFitter.cluster`` each, then ``enclose`` puts both kinds' clusters through
the first solve together (its cost is per iteration, not per set; each set's answer does not depend on the
others in the batch, all having 64 candidates, so the ellipsoids are those of one kind at a time, bit for bit).

Warm start. The fitter keeps the last chosen mixture and starts the next BIC search from it; voxel sets
change a little between iterations, so a few EM runs near the previous T suffice (``reset()`` forgets).
"""

from __future__ import annotations

import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike, NDArray

from planner import clustering
from planner.config import ClusterConfig
from planner.mixture import Mixture, Selection, assign
from planner.mvee import checked_points, solve
from planner.types import ClusterFit, Ellipsoid, EllipsoidKind

_ACTIVE_ROUNDS = 1  # re-solves with missed hull vertices added
_ADD_PER_ROUND = 16  # corners added per cluster and round
_MISS = 1e-2  # a corner this far outside (1 + _MISS) counts as a missed hull vertex
_CORNERS = np.array([[x, y, z] for x in (-0.5, 0.5) for y in (-0.5, 0.5) for z in (-0.5, 0.5)])  # voxel units


def _directions(k: int = 56) -> NDArray[np.float64]:  # 56 + 8 = 64 directions
    """(k + 8, 3) unit directions: a Fibonacci sphere plus the 8 cube diagonals."""
    i = np.arange(k) + 0.5
    z = 1.0 - 2.0 * i / k
    phi = np.pi * (1.0 + 5.0**0.5) * i
    r = np.sqrt(1.0 - z * z)
    fib = np.column_stack([r * np.cos(phi), r * np.sin(phi), z])
    return np.vstack([fib, _CORNERS / np.linalg.norm(_CORNERS, axis=1, keepdims=True)])


_DIRS = _directions()


def dense(labels: NDArray[np.int64]) -> NDArray[np.int32]:
    """(N,) component indices -> (N,) int32 ranks among the components that occur (the ellipsoids' order:
    ``_ellipsoids`` makes one per non-empty component, by component index)."""
    _, inverse = np.unique(labels, return_inverse=True)
    return inverse.reshape(-1).astype(np.int32)


class EllipsoidFitter:
    """Fits ellipsoids to the voxel centres of one kind, warm-starting each BIC search from the last one.

    config: the clustering settings; resolution: voxel edge, metres; kind: stamped on every ellipsoid.
    mvee_tol, mvee_max_iter, mvee_warmup: the MVEE solve (see ``planner.mvee``), tuned for speed.
    ``last_timings`` holds the seconds of the last fit: {"cluster": ..., "ellipsoids": ...}.
    """

    def __init__(
        self,
        config: ClusterConfig,
        resolution: float,
        kind: EllipsoidKind,
        *,
        mvee_tol: float = 1e-3,
        mvee_max_iter: int = 30,
        mvee_warmup: int = 50,
    ) -> None:
        if not np.isfinite(resolution) or resolution <= 0:
            raise ValueError(f"resolution: must be a finite number > 0, got {resolution!r}")
        if kind not in ("occupied", "frontier"):
            raise ValueError(f"kind: must be 'occupied' or 'frontier', got {kind!r}")
        self.config = config
        self.resolution = float(resolution)
        self.kind: EllipsoidKind = kind
        self.mvee_tol = mvee_tol
        self.mvee_max_iter = mvee_max_iter
        self.mvee_warmup = mvee_warmup
        self.last_timings: dict[str, float] = {}
        self._mixture: Mixture | None = None

    def reset(self) -> None:
        """Forget the warm-start state (the next fit searches T from scratch)."""
        self._mixture = None
        self.last_timings = {}

    @property
    def mixture(self) -> Mixture | None:
        """The last chosen mixture, in voxel units (points / resolution), or None."""
        return self._mixture

    def fit(
        self, points_world: ArrayLike, progress: Callable[[int, int], None] | None = None
    ) -> tuple[tuple[Ellipsoid, ...], ClusterFit]:
        """Ellipsoids of the clusters of ``points_world`` (N, 3) voxel centres, and the model selection.

        progress: ``(done, total)`` values of T fitted (the exhaustive search; the fast one reports its end)."""
        return fit_together([(self, points_world, progress)])[0]

    def cluster(self, points_world: ArrayLike, progress: Callable[[int, int], None] | None = None) -> Clusters:
        """The first half of :meth:`fit`: the BIC model selection of ``points_world`` (N, 3) and each voxel's
        cluster, with the clusters' hull candidates (what :func:`enclose` solves for); the warm start moves on."""
        p = checked_points("points_world", points_world)
        with clustering.single_thread_blas():
            t0 = time.perf_counter()
            if p.shape[0] == 0:
                return Clusters(self, 0, None, None, None, 0.0)
            x = p / self.resolution
            sel = clustering.select_mixture(x, self.config, self._mixture, progress)
            self._mixture = sel.mixture
            labels = assign(x, sel.mixture)
            hulls = _Hulls.of(x, labels)
            return Clusters(self, len(x), labels, sel, hulls, time.perf_counter() - t0)

    def fit_at(self, points_world: ArrayLike, t: int) -> tuple[tuple[Ellipsoid, ...], ClusterFit]:
        """Ellipsoids of ``points_world`` (N, 3), N >= 1, clustered by a GMM of exactly ``t`` components (no BIC
        search; scikit-learn's EM, seeded, as the exhaustive search fits it). The warm start is left alone: this
        answers "what would the fit look like at T", it is not the planner's fit. ``ClusterFit.bic`` holds
        (t, BIC of that model)."""
        p = checked_points("points_world", points_world, 1)
        if isinstance(t, bool) or not isinstance(t, int | np.integer) or not 1 <= int(t) <= p.shape[0]:
            raise ValueError(f"t: must be an integer in [1, {p.shape[0]}] (the points fitted), got {t!r}")
        t0 = time.perf_counter()
        x = p / self.resolution
        with clustering.single_thread_blas():
            bic, mix = clustering.fit_fixed_t(x, int(t), self.config)
            labels = assign(x, mix)
            hulls = _Hulls.of(x, labels)
            ellipsoids = self._enclosed(hulls, _solved([hulls], self._mvee)[0], mix)
        return ellipsoids, ClusterFit(
            self.kind, int(t), ((int(t), bic),), p.shape[0], time.perf_counter() - t0, dense(labels)
        )

    @property
    def _mvee(self) -> tuple[float, int, int]:
        return self.mvee_tol, self.mvee_max_iter, self.mvee_warmup

    def _enclosed(self, hulls: _Hulls, solved: _Solved, mix: Mixture) -> tuple[Ellipsoid, ...]:
        """One ellipsoid per non-empty cluster, ordered by component index, from the clusters' first MVEE solve:
        missed hull vertices added and solved again, then each scaled to contain every corner of its voxels."""
        xs, starts, counts, cand = hulls.xs, hulls.starts, hulls.counts, list(hulls.cand)
        centers, A, u = solved
        n_c = len(hulls.comps)
        seg = np.repeat(np.arange(n_c), counts)
        for round_ in range(_ACTIVE_ROUNDS + 1):
            # Every corner x + o_k of every voxel against its cluster's ellipsoid (1 = on the surface):
            # (y + o)^T A (y + o) = y^T A y + 2 o^T A y + o^T A o with y = x - c.
            y = xs - centers[seg]
            Ay = np.einsum("nij,nj->ni", A[seg], y)
            oAo = np.einsum("ki,cij,kj->ck", _CORNERS, A, _CORNERS)  # (C, 8)
            reach8 = np.einsum("ni,ni->n", y, Ay)[:, None] + 2.0 * Ay @ _CORNERS.T + oAo[seg]
            reach, corner = reach8.max(axis=1), reach8.argmax(axis=1)
            worst = np.maximum.reduceat(reach, starts)
            redo = np.flatnonzero(worst > 1.0 + _MISS)
            if len(redo) == 0 or round_ == _ACTIVE_ROUNDS:
                break
            # Missed hull vertices: add each such cluster's most violating corners, solve again from its weights.
            ranked = np.lexsort((-reach, seg))
            for ci in redo:
                pick = ranked[starts[ci] : starts[ci] + counts[ci]][:_ADD_PER_ROUND]
                pick = pick[reach[pick] > 1.0 + _MISS]
                cand[ci] = np.vstack([cand[ci], xs[pick] + _CORNERS[corner[pick]]])
                u[ci] = np.concatenate([u[ci], np.full(len(pick), 1.0 / len(u[ci]))])
            c2, A2, u2 = solve(
                [cand[ci] for ci in redo], [u[ci] for ci in redo], self.mvee_tol, self.mvee_max_iter, self.mvee_warmup
            )
            centers[redo], A[redo] = c2, A2
            for ci, uc in zip(redo, u2, strict=True):
                u[ci] = uc
        A = A / (np.maximum(worst, 1e-300) * (1.0 + 1e-12))[:, None, None]  # exact containment, tight
        out: list[Ellipsoid] = []
        res = self.resolution
        for ci, (comp, c) in enumerate(zip(hulls.comps, counts, strict=True)):
            lam, V = np.linalg.eigh(0.5 * (A[ci] + A[ci].T))
            if np.linalg.det(V) < 0:
                V[:, 2] = -V[:, 2]
            out.append(
                Ellipsoid(
                    center=centers[ci] * res,
                    axes=res / np.sqrt(lam),  # eigh sorts lam ascending: major axis first
                    rotation=V,
                    kind=self.kind,
                    n_points=int(c),
                    gmm_mean=mix.means[comp] * res,
                    gmm_covariance=mix.covariances[comp] * res**2,
                    gmm_weight=float(mix.weights[comp]),
                )
            )
        return tuple(out)


@dataclass(frozen=True, eq=False)
class _Hulls:
    """One kind's voxels sorted by cluster, and each cluster's hull candidates (voxel units).

    xs: (N, 3) centres by cluster; comps: (C,) the non-empty components; starts, counts: (C,) each cluster's
    rows of xs; cand: C x (K, 3) the cube corners extreme along the K = 64 fixed directions."""

    xs: NDArray[np.float64]
    comps: NDArray[np.int64]
    starts: NDArray[np.intp]
    counts: NDArray[np.intp]
    cand: tuple[NDArray[np.float64], ...]

    @staticmethod
    def of(x: NDArray[np.float64], labels: NDArray[np.int64]) -> _Hulls:
        """The hull candidates of the clusters ``labels`` (N,) of the centres x (N, 3), N >= 1."""
        order = np.argsort(labels, kind="stable")
        lab, xs = labels[order], x[order]
        comps, starts, counts = np.unique(lab, return_index=True, return_counts=True)
        n_c, n_d = len(comps), len(_DIRS)
        # The cube union's extreme point along each direction: an extreme centre + 0.5 sign(direction).
        proj = xs @ _DIRS.T  # (N, K)
        top = np.maximum.reduceat(proj, starts, axis=0)  # (C, K)
        rows, cols = np.nonzero(proj == np.repeat(top, counts, axis=0))
        key = np.repeat(np.arange(n_c), counts)[rows] * n_d + cols
        _, first = np.unique(key, return_index=True)  # one maximiser per (cluster, direction)
        cand = xs[rows[first].reshape(n_c, n_d)] + 0.5 * np.sign(_DIRS)[None]  # (C, K, 3)
        return _Hulls(xs, comps, starts, counts, tuple(cand))


_Solved = tuple[NDArray[np.float64], NDArray[np.float64], list[NDArray[np.float64]]]


def _solved(hulls: Sequence[_Hulls], mvee: tuple[float, int, int]) -> list[_Solved]:
    """The first MVEE solve of every cluster of every ``hulls``, in one batch (its cost is per iteration, not per
    set: two kinds cost about one; each set's answer does not depend on the others in the batch, all having K
    candidates), split back per hulls: (centres (C, 3), A (C, 3, 3), weights C x (K,))."""
    tol, max_iter, warmup = mvee
    centers, A, u = solve([c for h in hulls for c in h.cand], tol=tol, max_iter=max_iter, warmup=warmup)
    out: list[_Solved] = []
    at = 0
    for h in hulls:
        n = len(h.cand)
        out.append((centers[at : at + n].copy(), A[at : at + n].copy(), u[at : at + n]))
        at += n
    return out


@dataclass(frozen=True, eq=False)
class Clusters:
    """One kind's clusters (:meth:`EllipsoidFitter.cluster`), before their ellipsoids (:func:`enclose`).

    n_points: the voxels clustered (N); labels: (N,) each one's component; selection: the BIC model selection; hulls:
    the clusters' hull candidates; seconds: the clustering's wall time. labels, selection and hulls are None for no
    voxels."""

    fitter: EllipsoidFitter
    n_points: int
    labels: NDArray[np.int64] | None
    selection: Selection | None
    hulls: _Hulls | None
    seconds: float


def enclose(clusters: Sequence[Clusters]) -> list[tuple[tuple[Ellipsoid, ...], ClusterFit]]:
    """The ellipsoids and model selection of each :class:`Clusters` (its fitter's ``last_timings`` set): the first
    MVEE solve of all of them in one batch where their fitters' MVEE settings agree, then each kind's own."""
    with clustering.single_thread_blas():
        t0 = time.perf_counter()
        hulls = {i: c.hulls for i, c in enumerate(clusters) if c.hulls is not None}
        groups: dict[tuple[float, int, int], list[int]] = {}
        for i in hulls:
            groups.setdefault(clusters[i].fitter._mvee, []).append(i)
        solved: dict[int, _Solved] = {}
        for mvee, members in groups.items():
            solved.update(zip(members, _solved([hulls[i] for i in members], mvee), strict=True))
        shared = time.perf_counter() - t0
        total_sets = sum(len(h.cand) for h in hulls.values()) or 1
        out: list[tuple[tuple[Ellipsoid, ...], ClusterFit]] = []
        for i, c in enumerate(clusters):
            fitter = c.fitter
            t1 = time.perf_counter()
            if c.selection is None or c.hulls is None or c.labels is None:
                fitter.last_timings = {"cluster": 0.0, "ellipsoids": 0.0}
                out.append(((), ClusterFit(fitter.kind, 0, (), 0, 0.0)))
                continue
            mix = c.selection.mixture
            ellipsoids = fitter._enclosed(c.hulls, solved[i], mix)
            seconds = time.perf_counter() - t1 + shared * len(c.hulls.cand) / total_sets  # its share of the batch
            fitter.last_timings = {"cluster": c.seconds, "ellipsoids": seconds}
            fit = ClusterFit(
                fitter.kind,
                mix.n_components,
                tuple(sorted(c.selection.evaluated.items())),
                c.n_points,
                c.seconds + seconds,
                dense(c.labels),
            )
            out.append((ellipsoids, fit))
        return out


def fit_together(
    jobs: Sequence[tuple[EllipsoidFitter, ArrayLike, Callable[[int, int], None] | None]],
) -> list[tuple[tuple[Ellipsoid, ...], ClusterFit]]:
    """:meth:`EllipsoidFitter.fit` of each (fitter, points (N, 3), progress), the MVEE solves batched
    (:func:`enclose`): the same ellipsoids as one fit at a time, in less time."""
    return enclose([fitter.cluster(points, progress) for fitter, points, progress in jobs])


def fit_at_t(
    points_world: ArrayLike, config: ClusterConfig, resolution: float, kind: EllipsoidKind, t: int
) -> tuple[tuple[Ellipsoid, ...], ClusterFit]:
    """:meth:`EllipsoidFitter.fit_at` of a fresh fitter: the ellipsoids of ``points_world`` (N, 3) at exactly T."""
    return EllipsoidFitter(config, resolution, kind).fit_at(points_world, t)
