"""Global longitude partitions and the final choice of the next best view (paper §III-F).

The candidate hemisphere is cut into ``beta`` longitude sectors. Sector ``k``
covers the azimuths ``[offset + k * 2 pi / beta, offset + (k + 1) * 2 pi / beta)``
(mod 2 pi), azimuth measured about the hemisphere centre in the world (turntable)
frame, counter-clockwise from world +x seen from above.

Rule (paper): until every sector has been scanned, the next view may only come
from an *unscanned* sector adjacent (cyclically) to a scanned one, so the scan
sweeps around the object without jumps that would break frame-to-frame ICP.
Once every sector has been scanned, every sector is eligible again. Before the
first view (nothing scanned) every sector is eligible.

Also here: ``not_taken`` (candidates within an angle of a view already taken are
not proposed; ``Planner`` uses ``PartitionConfig.revisit_deg``, 30 degrees, a
departure measured in docs/experiments/departures.md) and ``select_best`` (argmax of F over the
eligible candidates).
"""

from __future__ import annotations

import math
from collections.abc import Sequence

import numpy as np
from numpy.typing import ArrayLike, NDArray

from planner.config import PartitionConfig
from planner.types import Candidate, Pose, ViewScore

TWO_PI = 2.0 * math.pi
EDGE_TOL = 1e-9
"""Azimuths less than this (rad) below a sector edge count as on it, so the same direction computed
two ways (a candidate's exact azimuth, ``azimuth_of`` its position) lands in the same sector."""


def _check_config(config: PartitionConfig) -> None:
    if not isinstance(config, PartitionConfig):
        raise ValueError(f"config: expected a PartitionConfig, got {type(config).__name__}")


def sector_of(azimuth: float, config: PartitionConfig) -> int:
    """Index in ``[0, beta)`` of the sector containing ``azimuth`` (rad, any real value; see EDGE_TOL)."""
    _check_config(config)
    if not math.isfinite(azimuth):
        raise ValueError(f"azimuth: must be finite, got {azimuth!r}")
    width = TWO_PI / config.sectors
    rel = (azimuth - math.radians(config.offset_deg) + EDGE_TOL) % TWO_PI
    return min(int(rel // width), config.sectors - 1)


def sector_edges(config: PartitionConfig) -> NDArray[np.float64]:
    """(beta,) float64: the azimuth (rad, in [0, 2 pi)) where sector k starts, indexed by k."""
    _check_config(config)
    k = np.arange(config.sectors, dtype=np.float64)
    return np.mod(math.radians(config.offset_deg) + k * TWO_PI / config.sectors, TWO_PI)


def eligible_sectors(scanned: set[int] | frozenset[int], n: int) -> set[int]:
    """Sectors the next view may come from, given the ``scanned`` ones, out of ``n``.

    Nothing scanned or everything scanned -> all ``n``; otherwise the unscanned
    sectors with a scanned cyclic neighbour (k - 1 or k + 1 mod n).
    """
    if not isinstance(n, int) or n < 1:
        raise ValueError(f"n: must be an integer >= 1, got {n!r}")
    bad = [k for k in scanned if not isinstance(k, int | np.integer) or not 0 <= k < n]
    if bad:
        raise ValueError(f"scanned: sector indices must be integers in [0, {n}), got {sorted(map(str, bad))}")
    done = {int(k) for k in scanned}
    if not done or len(done) == n:
        return set(range(n))
    return {k for k in range(n) if k not in done and ((k - 1) % n in done or (k + 1) % n in done)}


def azimuth_of(position_world: ArrayLike, center: ArrayLike) -> float:
    """Azimuth (rad, in [0, 2 pi)) of ``position_world`` (3,) about ``center`` (3,), from +x towards +y."""
    p = np.asarray(position_world, dtype=np.float64)
    c = np.asarray(center, dtype=np.float64)
    if p.shape != (3,) or not np.all(np.isfinite(p)):
        raise ValueError(f"position_world: expected 3 finite values, got shape {p.shape}")
    if c.shape != (3,) or not np.all(np.isfinite(c)):
        raise ValueError(f"center: expected 3 finite values, got shape {c.shape}")
    a = math.atan2(p[1] - c[1], p[0] - c[0]) % TWO_PI
    return 0.0 if a >= TWO_PI else a  # -0.0 % 2pi and tiny negatives can round to 2 pi


def _unit_rows(v: NDArray[np.float64], name: str) -> NDArray[np.float64]:
    n = np.linalg.norm(v, axis=1, keepdims=True)
    if np.any(n < 1e-12):
        raise ValueError(f"{name}: a view sits at the hemisphere centre (no direction)")
    return v / n


def _directions(poses: Sequence[Pose], center: NDArray[np.float64] | None, name: str) -> NDArray[np.float64]:
    """(N, 3) unit directions "from the centre to the camera" of ``poses``.

    With a centre: the normalised ``position - center``. Without: minus the optical
    axis (exact for views that look at the centre, as every candidate does).
    """
    if not poses:
        return np.zeros((0, 3))
    if center is None:
        return _unit_rows(-np.stack([p.rotation[:, 2] for p in poses]), name)
    return _unit_rows(np.stack([p.translation for p in poses]) - center, name)


def _check_center(center: ArrayLike | None) -> NDArray[np.float64] | None:
    if center is None:
        return None
    c = np.asarray(center, dtype=np.float64)
    if c.shape != (3,) or not np.all(np.isfinite(c)):
        raise ValueError(f"center: expected 3 finite values, got shape {c.shape}")
    return c


def _check_candidates(candidates: Sequence[Candidate]) -> None:
    for i, c in enumerate(candidates):
        if not isinstance(c, Candidate):
            raise ValueError(f"candidates[{i}]: expected a Candidate, got {type(c).__name__}")


def not_taken(
    candidates: Sequence[Candidate],
    taken: Sequence[Pose],
    tolerance_rad: float,
    center: ArrayLike | None = None,
) -> NDArray[np.bool_]:
    """(C,) bool: True where no taken view's direction is within ``tolerance_rad`` of the candidate's.

    Directions, not positions, are compared because the hemisphere radius (and a
    little its centre) changes between iterations as B grows. With ``center``
    (3,) the direction of a view is ``position - center``; without it, minus its
    optical axis (the same thing for views that looked at the centre).
    """
    _check_candidates(candidates)
    if not math.isfinite(tolerance_rad) or tolerance_rad < 0:
        raise ValueError(f"tolerance_rad: must be a finite number >= 0, got {tolerance_rad!r}")
    for i, p in enumerate(taken):
        if not isinstance(p, Pose):
            raise ValueError(f"taken[{i}]: expected a Pose, got {type(p).__name__}")
    c = _check_center(center)
    out = np.ones(len(candidates), dtype=bool)
    if not candidates or not taken:
        return out
    d_cand = _directions([k.T_world_camera for k in candidates], c, "candidates")
    d_taken = _directions(list(taken), c, "taken")
    cos = np.clip(d_cand @ d_taken.T, -1.0, 1.0)  # (C, V)
    angle = np.arccos(cos)
    out &= ~np.any(angle <= tolerance_rad, axis=1)
    return out


def default_tolerance(candidates: Sequence[Candidate], center: ArrayLike | None = None) -> float:
    """Half the mean angular spacing (rad) between candidates: mean nearest-neighbour angle / 2.

    Directions as in ``not_taken``. Fewer than two candidates -> 0.0 (no spacing to speak of).
    """
    _check_candidates(candidates)
    if len(candidates) < 2:
        return 0.0
    d = _directions([k.T_world_camera for k in candidates], _check_center(center), "candidates")
    cos = np.clip(d @ d.T, -1.0, 1.0)
    np.fill_diagonal(cos, -1.0)
    nearest = np.arccos(cos.max(axis=1))
    return 0.5 * float(nearest.mean())


def select_best(scores: Sequence[ViewScore]) -> int | None:
    """Position in ``scores`` of the eligible view with the largest F; None if none is eligible.

    Ties go to the lowest position. Ineligible views are ignored whatever their score.
    """
    best: int | None = None
    best_score = -math.inf
    for i, s in enumerate(scores):
        if not isinstance(s, ViewScore):
            raise ValueError(f"scores[{i}]: expected a ViewScore, got {type(s).__name__}")
        if math.isnan(s.score):
            raise ValueError(f"scores[{i}]: score is NaN")
        if s.eligible and (best is None or s.score > best_score):
            best, best_score = i, s.score
    return best


def select_with_move_cost(scores: Sequence[ViewScore], move_seconds: NDArray[np.float64], weight: float) -> int | None:
    """Position of the eligible view maximising ``F / max|F| - weight * t / max t`` (both maxima over the eligible
    views with a finite t), ``move_seconds`` (C,) the move time per view (inf = unknown: not chosen while another
    view has a finite time). ``weight`` 0 is :func:`select_best`. Ties go to the lowest position."""
    if weight == 0:
        return select_best(scores)
    t = np.asarray(move_seconds, dtype=np.float64)
    if t.shape != (len(scores),):
        raise ValueError(f"move_seconds: expected shape ({len(scores)},), got {t.shape}")
    eligible = np.array([s.eligible for s in scores], dtype=bool)
    usable = eligible & np.isfinite(t)
    if not np.any(usable):
        return select_best(scores)
    f = np.array([s.score for s in scores], dtype=np.float64)
    f_scale = max(float(np.max(np.abs(f[usable]))), 1e-12)
    t_scale = max(float(np.max(t[usable])), 1e-12)
    utility = np.where(usable, f / f_scale - weight * np.where(usable, t, 0.0) / t_scale, -np.inf)
    return int(np.argmax(utility))
