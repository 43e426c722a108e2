"""The projection-based viewpoint quality F (paper §III-E).

For each candidate view:

1. Depth ranks. Every ellipsoid centre (both kinds together) goes into the camera
   frame, ``C = R^T (c_w - t)``, and the centres are sorted by ascending z; the
   nearest gets rank ``r = 0``. Ranks are the *inverse* permutation of the sort,
   ``argsort(argsort(z))`` (the authors' code uses the argsort output itself as
   ranks, which gives the rank of the wrong ellipsoid). Equal depths keep input order.
   Ellipsoids whose centre is behind the camera (``z <= 0``) take no part in the
   ranking: rank -1, weight 0 (the pinhole model has no image of them; counting their
   ranks would also push visible ellipsoids to smaller weights).
2. Weights ``W = rank_base ** r`` (paper: 0.5).
3. ``L`` = pixels inside each ellipsoid's projected outline (``planner.projection``),
   ``L_hat = W * L``.
4. ``F = sum(L_hat over frontier) - sum(L_hat over occupied)``.

Every candidate is scored, eligible or not, so the UI can show why a view lost;
``planner.partitions.select_best`` ignores the ineligible ones.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np
from numpy.typing import ArrayLike, NDArray

from planner.config import ScoringConfig
from planner.projection import project
from planner.types import Candidate, Ellipsoid, Intrinsics, ViewScore


def depth_ranks(z: NDArray[np.float64]) -> NDArray[np.int64]:
    """(C, E) int64 depth ranks of camera-frame depths z (C, E); -1 where ``z <= 0``.

    Among the centres in front, the nearest is 0, the next 1, ...; ties keep input order.
    """
    z = np.asarray(z, dtype=np.float64)
    if z.ndim != 2:
        raise ValueError(f"z: expected shape (C, E), got {z.shape}")
    front = z > 0
    keyed = np.where(front, z, np.inf)  # behind-camera centres sort last ...
    ranks = np.argsort(np.argsort(keyed, axis=1, kind="stable"), axis=1, kind="stable").astype(np.int64)
    ranks[~front] = -1  # ... and are then taken out
    return ranks


def rank_weights(ranks: NDArray[np.int64], rank_base: float) -> NDArray[np.float64]:
    """W = rank_base ** rank, 0 where rank == -1 (same shape as ``ranks``)."""
    r = np.asarray(ranks)
    return np.where(r >= 0, float(rank_base) ** np.maximum(r, 0), 0.0)


def _check_inputs(
    ellipsoids: Sequence[Ellipsoid],
    candidates: Sequence[Candidate],
    intrinsics: Intrinsics,
    config: ScoringConfig,
    eligible: ArrayLike,
) -> NDArray[np.bool_]:
    for i, e in enumerate(ellipsoids):
        if not isinstance(e, Ellipsoid):
            raise ValueError(f"ellipsoids[{i}]: expected an Ellipsoid, got {type(e).__name__}")
    for i, c in enumerate(candidates):
        if not isinstance(c, Candidate):
            raise ValueError(f"candidates[{i}]: expected a Candidate, got {type(c).__name__}")
    if not isinstance(intrinsics, Intrinsics):
        raise ValueError(f"intrinsics: expected an Intrinsics, got {type(intrinsics).__name__}")
    if not isinstance(config, ScoringConfig):
        raise ValueError(f"config: expected a ScoringConfig, got {type(config).__name__}")
    mask = np.asarray(eligible)
    if mask.shape != (len(candidates),):
        raise ValueError(f"eligible: expected shape ({len(candidates)},), got {mask.shape}")
    if mask.size and mask.dtype != np.bool_:
        raise ValueError(f"eligible: expected a bool array, got dtype {mask.dtype}")
    return mask.astype(bool)


def score_views(
    ellipsoids: Sequence[Ellipsoid],
    candidates: Sequence[Candidate],
    intrinsics: Intrinsics,
    config: ScoringConfig,
    eligible: ArrayLike,
) -> tuple[ViewScore, ...]:
    """Score every candidate (C) against every ellipsoid (E) -> C ViewScores, in candidate order.

    eligible: (C,) bool, copied into ``ViewScore.eligible``; it does not change any score.
    Per-ellipsoid arrays of each ViewScore (length E) follow the order of ``ellipsoids``.
    """
    mask = _check_inputs(ellipsoids, candidates, intrinsics, config, eligible)
    if not candidates:
        return ()
    proj = project(ellipsoids, [c.T_world_camera for c in candidates], intrinsics, area=config.area)
    ranks = depth_ranks(proj.centers_camera[..., 2])  # (C, E)
    weights = rank_weights(ranks, config.rank_base)
    pixels = proj.pixels
    weighted = weights * pixels
    is_frontier = np.array([e.kind == "frontier" for e in ellipsoids], dtype=bool)
    frontier = weighted[:, is_frontier].sum(axis=1)
    occupied = weighted[:, ~is_frontier].sum(axis=1)
    score = frontier - occupied
    for a in (ranks, weights, weighted):
        a.setflags(write=False)
    return view_scores(candidates, mask, score, frontier, occupied, ranks, weights, pixels, weighted)


def view_scores(
    candidates: Sequence[Candidate],
    eligible: NDArray[np.bool_],
    score: NDArray[np.float64],
    frontier: NDArray[np.float64],
    occupied: NDArray[np.float64],
    ranks: NDArray[np.int64],
    weights: NDArray[np.float64],
    pixels: NDArray[np.float64],
    weighted: NDArray[np.float64],
) -> tuple[ViewScore, ...]:
    """One :class:`ViewScore` per candidate from (C,) totals and (C, E) per-ellipsoid terms (row i: candidate i)."""
    columns = (score.tolist(), frontier.tolist(), occupied.tolist(), np.asarray(eligible, dtype=bool).tolist())
    rows = (ranks, weights, pixels, weighted)  # iterating a (C, E) array gives its rows: no index a candidate
    return tuple(
        ViewScore(c.index, s, f, o, e, r, w, p, x)
        for c, s, f, o, e, r, w, p, x in zip(candidates, *columns, *rows, strict=True)
    )
