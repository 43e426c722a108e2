"""The ``tour`` planner: a receding-horizon tour of views that together cover the predicted frontier, in the order
the robot reaches them fastest (not in the paper: it minimises robot time to coverage).

The paper's greedy rule (§III-F) picks the single view with the largest score F and never looks at what the move
costs; in the simulated UR5 cell the robot's moves are about 97 % of a scan's time. Each plan here:

1. **Visibility** (:func:`visible_frontier`): which frontier voxels each eligible candidate sees. Every frontier
   and occupied voxel centre is projected into a coarse ``w x h`` raster of the candidate camera; a z-buffer keeps
   the nearest depth per raster pixel (min over a 3 x 3 block, so a surface one voxel apart has no holes); a
   frontier voxel is seen when it lies in the image, in front of the camera, and at most
   ``tour.depth_tolerance_voxels`` behind the z-buffer at its pixel. Result: ``seen`` (C, F) bool.
2. **Set cover** (:func:`greedy_cover`): the greedy set cover of the frontier the eligible views see: repeatedly the
   view that sees the most frontier voxels *not yet covered* by the views chosen before it (overlap counts once),
   until ``tour.horizon`` views or the next would add less than ``tour.min_gain`` of the coverable frontier.
3. **Order** (:func:`tour_order`): the shortest open path from the robot's current state through the chosen views
   under the cell's move times (``move_times``: plate turn + the slowest joint's trapezoid, from the arm's cached
   IK targets; the caller gives them, the planner never sees the arm): an asymmetric TSP with a free return to the
   start, solved by LKH (``elkai``) from three views on, exactly below.
4. The first view of the order is the next view; the rest is the predicted tour (``PlanResult.tour``), re-planned
   after every capture.

With ``tour.opening = "ring"`` the scan's first plans come before the tour (:func:`ring_view`): a turntable
scanner's ring of low views about ``tour.ring_spread_deg`` either side of the scan's first view, which the oracle's
sequences share across objects (docs/experiments/tour.md); each plan takes the shortest move among the
ring views that see the most frontier, until both sides of the ring hold a view.

With ``tour.lazy_reach`` (the default) the plan skips its reachability pass over every candidate
(:attr:`TourEvaluator.lazy_reach`): the cover's views are the only ones the cell is asked about, through their move
times (inf: unreachable; the view is left out and the cover made again). With ``tour.score = "projection"`` the
plan instead scores by the paper's F and takes the shortest exact move among the views within ``tour.slack`` of the
best F (:func:`near_best`; tried, not the default).
"""

from __future__ import annotations

import itertools
import math
import time
from collections.abc import Callable, Sequence

import numpy as np
from numpy.typing import NDArray

from planner.config import PlannerConfig, TourConfig
from planner.evaluators import EVALUATORS, Evaluation, EvaluationContext, ProjectionEvaluator
from planner.partitions import TWO_PI, azimuth_of
from planner.types import CameraPath, Candidate, Intrinsics, MovePaths, Pose, TourPlan, ViewScore, VoxelClass

MoveTimes = Callable[..., NDArray[np.float64]]
"""(candidates, K indices[, exact=bool]) -> (K + 1, K + 1) seconds of the move between every two states; state 0 is
the robot's current one, state k the candidate ``indices[k - 1]``; inf for a move the cell cannot make. ``exact``
(``devices.cell.Cell.move_times``): each view's target as a move from the current state would choose it (every
plate angle and IK branch), not the cached reachability target; asked with ``tour.score = "projection"``."""

FALLBACK_SPEED = 0.25
"""m/s of the camera's straight travel assumed when the caller gives no move times (a cell without an arm model)."""
UNKNOWN_MOVE = 1e4
"""Seconds put on a move between two tour views that the cell gave as inf (the path then avoids it)."""
MAX_EXACT = 7
"""Most views :func:`rate_order` enumerates (7! = 5040 orders)."""
CAMERAS_PER_BATCH = 16
"""Candidates projected together in :func:`visible_frontier`: a batch's z-buffer (16 x 122 x 162 float64, 2.5 MB)
stays in the processor's cache; 48 a batch measured twice as slow (7.6 MB to fill and read), 8 no faster than 16."""


def visible_frontier(
    frontier: NDArray[np.float64],
    occluders: NDArray[np.float64],
    poses: Sequence[Pose],
    intrinsics: Intrinsics,
    width: int,
    height: int,
    tolerance: float,
) -> NDArray[np.bool_]:
    """(C, F) bool: frontier voxel f is seen from camera c (see the module docstring, step 1).

    frontier: (F, 3) frontier voxel centres; occluders: (N, 3) the other voxels that hide them (occupied),
    world frame, metres. poses: C ``T_world_camera``. width, height: the raster. tolerance: metres.
    """
    frontier = np.asarray(frontier, dtype=np.float64).reshape(-1, 3)
    points = np.concatenate([frontier, np.asarray(occluders, dtype=np.float64).reshape(-1, 3)])
    n_f = len(frontier)
    seen = np.zeros((len(poses), n_f), dtype=bool)
    if n_f == 0 or len(poses) == 0:
        return seen
    k = intrinsics
    sx, sy = width / k.width, height / k.height
    row = width + 2  # the raster with a border of one pixel at inf, so a 3 x 3 block never leaves it
    block = np.array([dy * row + dx for dy in (-1, 0, 1) for dx in (-1, 0, 1)], dtype=np.int64)  # (9,)
    for start in range(0, len(poses), CAMERAS_PER_BATCH):
        batch = poses[start : start + CAMERAS_PER_BATCH]
        R = np.stack([p.rotation for p in batch])  # (B, 3, 3) camera axes in the world
        t = np.stack([p.translation for p in batch])  # (B, 3)
        X = points @ R - (t[:, None, :] @ R)  # (B, P, 3): R^T (p - t), the camera frame
        z = X[..., 2]
        with np.errstate(divide="ignore", invalid="ignore"):
            u = (k.fx * X[..., 0] / z + k.cx + 0.5) * sx
            v = (k.fy * X[..., 1] / z + k.cy + 0.5) * sy
        ok = (z > 1e-6) & (u >= 0) & (u < width) & (v >= 0) & (v < height)
        cam = np.broadcast_to(np.arange(len(batch))[:, None], z.shape)
        pixel = cam * (row * (height + 2)) + (np.floor(v).astype(np.int64).clip(0, height - 1) + 1) * row
        pixel += np.floor(u).astype(np.int64).clip(0, width - 1) + 1
        zbuf = np.full(len(batch) * row * (height + 2), np.inf)
        np.minimum.at(zbuf, pixel[ok], z[ok])
        front = pixel[:, :n_f]
        near = zbuf[front[..., None] + block].min(axis=-1)  # (B, F): the 3 x 3 minimum at each frontier pixel only
        seen[start : start + len(batch)] = ok[:, :n_f] & (z[:, :n_f] <= near + tolerance)
    return seen


def greedy_cover(
    seen: NDArray[np.bool_], allowed: NDArray[np.bool_], horizon: int, min_gain: float
) -> tuple[list[int], list[int]]:
    """(views, gains): the greedy set cover of the frontier the ``allowed`` views see.

    seen: (C, F) bool (:func:`visible_frontier`); allowed: (C,) bool. Each step takes the allowed view that sees
    the most frontier voxels not yet covered (the lowest index on a tie); ``gains`` are those new counts, so a
    voxel two chosen views see counts once. Stops after ``horizon`` views, or when the best new count is 0 or
    below ``min_gain`` x the voxels all allowed views see together.
    """
    seen = np.asarray(seen, dtype=bool) & np.asarray(allowed, dtype=bool)[:, None]
    coverable = int(seen.any(axis=0).sum())
    covered = np.zeros(seen.shape[1], dtype=bool)
    views: list[int] = []
    gains: list[int] = []
    while len(views) < horizon:
        gain = (seen & ~covered).sum(axis=1)
        gain[views] = -1
        best = int(np.argmax(gain))
        if gain[best] <= 0 or gain[best] < min_gain * coverable:
            break
        views.append(best)
        gains.append(int(gain[best]))
        covered |= seen[best]
    return views, gains


def tour_order(times: NDArray[np.float64], start_with: int | None = None) -> tuple[list[int], str]:
    """(order, method): the states 1..K of ``times`` in the order of the shortest open path from state 0.

    times: (K + 1, K + 1) seconds from state i to state j (finite; the return to 0 is free). start_with: a state
    the path must visit first (None: any). method: "exact" (enumerated, K <= 2 or the rest after start_with <= 2)
    or "lkh" (elkai's LKH-3, from three states on).
    """
    times = np.asarray(times, dtype=np.float64)
    n = len(times) - 1
    if times.shape != (n + 1, n + 1) or not np.all(np.isfinite(times)):
        raise ValueError(f"times: need a finite ({n + 1}, {n + 1}) matrix, got shape {times.shape}")
    if n == 0:
        return [], "exact"
    if start_with is not None:
        rest = [i for i in range(1, n + 1) if i != start_with]
        sub = times[np.ix_([start_with, *rest], [start_with, *rest])]
        order, method = tour_order(sub)
        return [start_with, *(rest[i - 1] for i in order)], method
    if n <= 2:
        best = min(itertools.permutations(range(1, n + 1)), key=lambda p: path_seconds(times, list(p)))
        return list(best), "exact"
    import elkai

    cost = np.rint(times * 1000.0).astype(np.int64)  # integer milliseconds for LKH
    cost[:, 0] = 0  # an open path: returning to the start is free
    tour = elkai.DistanceMatrix(cost.tolist()).solve_tsp()
    order = [int(i) for i in tour if i != 0]
    return order, "lkh"


def rate_order(times: NDArray[np.float64], gains: Sequence[float], overhead: float) -> list[int]:
    """The order of states 1..K of ``times`` ((K + 1, K + 1), from state 0) that minimises sum_k gain_k * t_k,
    t_k the seconds at which view k is captured (its arrival plus ``overhead`` seconds per view before it): the
    order with the largest area under the predicted coverage-against-robot-time curve (the weighted completion
    time of a sequence with setup times). Exact: every permutation, K <= :data:`MAX_EXACT`."""
    times = np.asarray(times, dtype=np.float64)
    n = len(times) - 1
    if n == 0:
        return []
    if n > MAX_EXACT:
        raise ValueError(f"rate_order: at most {MAX_EXACT} views, got {n}")
    perms = np.array(list(itertools.permutations(range(1, n + 1))), dtype=np.int64)  # (P, K)
    states = np.concatenate([np.zeros((len(perms), 1), dtype=np.int64), perms], axis=1)
    legs = times[states[:, :-1], states[:, 1:]] + overhead  # (P, K)
    arrival = np.cumsum(legs, axis=1)
    g = np.asarray(gains, dtype=np.float64)[perms - 1]
    best = int(np.argmin((g * arrival).sum(axis=1)))
    return [int(i) for i in perms[best]]


def path_seconds(times: NDArray[np.float64], order: Sequence[int]) -> float:
    """Seconds of the open path 0 -> order[0] -> order[1] ... under ``times`` ((K + 1, K + 1))."""
    states = [0, *order]
    return float(sum(times[a, b] for a, b in itertools.pairwise(states)))


def near_best(
    ranked: Sequence[tuple[int, float]],
    seconds: Callable[[list[int]], NDArray[np.float64]],
    slack: float,
    near_views: int,
) -> tuple[int | None, dict[int, float]]:
    """(the next view, {view: move seconds} of every view timed): the shortest move among the views scoring
    nearly the best.

    ranked: (candidate index, F) of the eligible views, best F first. seconds: K indices -> (K,) seconds of the
    move to each from the current state (inf: the cell cannot reach it; this is the views' only reachability
    check). Views are timed best F first, ``near_views`` at a time, while their F is at least (1 - ``slack``) x the
    best F (every view when the best F <= 0), until ``near_views`` reachable ones are timed; the next view is the
    timed reachable one with the shortest move (on a tie the better F). None when none timed is reachable.
    """
    if not ranked:
        return None, {}
    top = ranked[0][1]
    threshold = (1.0 - slack) * top if top > 0 else -math.inf
    timed: dict[int, float] = {}
    start = 0
    while start < len(ranked) and ranked[start][1] >= threshold:
        batch = [i for i, f in ranked[start : start + near_views] if f >= threshold]
        start += near_views
        timed.update(zip(batch, (float(t) for t in seconds(batch)), strict=True))
        if sum(math.isfinite(t) for t in timed.values()) >= near_views:
            break
    order = [i for i, _ in ranked if i in timed and math.isfinite(timed[i])]
    if not order:
        return None, timed
    return min(order, key=lambda i: timed[i]), timed  # min keeps the first (better F) on a tie


def azimuth_gap(a: float | NDArray[np.float64], b: float) -> NDArray[np.float64]:
    """The angle (rad, in [0, pi]) between azimuths ``a`` (any shape) and ``b``, the short way round."""
    d = np.mod(np.asarray(a, dtype=np.float64) - b, TWO_PI)
    return np.minimum(d, TWO_PI - d)


def ring_directions(first: float, spread: float, taken: Sequence[float], tolerance: float) -> list[float]:
    """The ring's azimuths (rad) still open: ``first`` + ``spread`` and ``first`` - ``spread`` (the scan's first
    view's azimuth about the object, either side), each unless a view taken since (``taken``: their azimuths) lies
    within ``tolerance`` of it. One azimuth when ``spread`` is pi (both sides meet behind the object)."""
    sides = [first + spread] if math.isclose(spread, math.pi) else [first + spread, first - spread]
    return [float(d % TWO_PI) for d in sides if not any(float(azimuth_gap(a, d)) <= tolerance for a in taken)]


def ring_view(
    counts: NDArray[np.float64],
    eligible: NDArray[np.bool_],
    azimuths: NDArray[np.float64],
    elevations: NDArray[np.float64],
    directions: Sequence[float],
    max_elevation: float,
    tolerance: float,
    share: float,
    seconds: Callable[[list[int]], NDArray[np.float64]],
    near_views: int,
) -> tuple[int | None, dict[int, float]]:
    """(the ring's next view, {view: move seconds} of every view timed) (:func:`near_best` over the ring's views).

    counts: (C,) frontier voxels each candidate sees; eligible: (C,) bool; azimuths, elevations: (C,) rad about the
    object's box centre. A ring view is eligible, sees some frontier, lies at most ``max_elevation`` high and within
    ``tolerance`` (rad) in azimuth of one of ``directions`` (:func:`ring_directions`). Of the ring views that see at
    least ``share`` x the most any of them sees, the ``near_views`` reachable ones that see the most are timed by
    ``seconds`` (K indices -> (K,) seconds of each move from the current state, inf: unreachable) and the shortest
    move wins. (None, {}) when no view is a ring view, (None, timed) when none timed is reachable.
    """
    counts = np.asarray(counts, dtype=np.float64)
    ring = np.asarray(eligible, dtype=bool) & ring_mask(
        counts, azimuths, elevations, directions, max_elevation, tolerance
    )
    ranked = sorted(((int(i), float(counts[i])) for i in np.flatnonzero(ring)), key=lambda t: (-t[1], t[0]))
    return near_best(ranked, seconds, 1.0 - share, near_views)


def ring_mask(
    counts: NDArray[np.float64],
    azimuths: NDArray[np.float64],
    elevations: NDArray[np.float64],
    directions: Sequence[float],
    max_elevation: float,
    tolerance: float,
) -> NDArray[np.bool_]:
    """(C,) bool: the ring's views (eligibility aside): seeing some frontier (``counts`` (C,) > 0), at most
    ``max_elevation`` high and within ``tolerance`` in azimuth of one of ``directions`` (rad; :func:`ring_view`)."""
    near = np.zeros(len(counts), dtype=bool)
    for d in directions:
        near |= azimuth_gap(azimuths, d) <= tolerance
    return near & (np.asarray(elevations) <= max_elevation) & (np.asarray(counts) > 0)


def other_side(
    counts: NDArray[np.float64],
    azimuths: NDArray[np.float64],
    elevations: NDArray[np.float64],
    direction: float,
    max_elevation: float,
    tolerance: float,
    share: float,
    near_views: int,
) -> tuple[int, ...]:
    """The ring views about azimuth ``direction`` (rad) the ring's next plan is expected to time (:func:`ring_view`'s
    rule on this plan's counts): at most ``max_elevation`` high, within ``tolerance`` of ``direction``, seeing at least
    ``share`` x the most any of them sees (``counts`` (C,): the frontier voxels each sees now, 0 for a view not
    eligible in this plan, so a side the partitions still lock names only its views in an open sector), the
    ``near_views`` that see the most, most first. ``TourPlan.then`` of the ring's first plan."""
    counts = np.asarray(counts, dtype=np.float64)
    ring = ring_mask(counts, azimuths, elevations, [direction], max_elevation, tolerance)
    if not np.any(ring):
        return ()
    ring &= counts >= share * counts[ring].max()
    ranked = sorted((int(i) for i in np.flatnonzero(ring)), key=lambda i: (-counts[i], i))
    return tuple(ranked[:near_views])


def low_views(
    eligible: NDArray[np.bool_], seen: NDArray[np.bool_], candidates: Sequence[Candidate], max_elevation_deg: float
) -> NDArray[np.bool_]:
    """(C,) bool: the views the cover may take, ``eligible`` (C,) and at most ``max_elevation_deg`` high (about the
    box centre, ``Candidate.elevation``), unless none of those sees any frontier (``seen`` (C, F)): then every
    eligible view. 90 or more, or no ``candidates`` given (their elevations unknown): every eligible view. (After the
    ring, views above 25 deg were predicted a few frontier voxels each and cleared almost none:
    docs/experiments/tour.md.)"""
    allowed = np.asarray(eligible, dtype=bool).copy()
    if max_elevation_deg >= 90 or len(candidates) != len(allowed):
        return allowed
    low = np.array([c.elevation <= math.radians(max_elevation_deg) for c in candidates], dtype=bool)
    if np.any(allowed & low & np.asarray(seen, dtype=bool).any(axis=1)):
        allowed &= low
    return allowed


def seconds_from_here(
    move_times: MoveTimes | None, candidates: Sequence[Candidate], start: Pose
) -> Callable[[list[int]], NDArray[np.float64]]:
    """K indices -> (K,) seconds of the move from the current state to each of those ``candidates``, as the cell would
    make it (``move_times(..., exact=True)``: every plate angle and IK branch; inf: unreachable); without
    ``move_times``, straight lines from ``start`` (:func:`straight_move_times`). What :func:`near_best` and
    :func:`ring_view` time their views by."""

    def seconds(views: list[int]) -> NDArray[np.float64]:
        if move_times is not None:
            return np.asarray(move_times(candidates, views, exact=True), dtype=np.float64)[0, 1:]
        return straight_move_times(start, [candidates[i].T_world_camera for i in views])[0, 1:]

    return seconds


def straight_move_times(start: Pose, poses: Sequence[Pose]) -> NDArray[np.float64]:
    """(K + 1, K + 1) seconds between ``start`` and every two of ``poses`` at :data:`FALLBACK_SPEED` along straight
    lines: the move times of a cell that gives none."""
    xyz = np.stack([start.translation, *(p.translation for p in poses)])
    return np.linalg.norm(xyz[:, None, :] - xyz[None, :, :], axis=2) / FALLBACK_SPEED


class TourEvaluator:
    """Scores each candidate by the frontier voxels it sees (:func:`visible_frontier`) and chooses by the tour."""

    name = "tour"
    stages = ("visibility", "tour")

    def __init__(self, config: PlannerConfig) -> None:
        self.config = config
        self.last_seen: NDArray[np.bool_] = np.zeros((0, 0), dtype=bool)
        self.last_frontier: NDArray[np.float64] = np.zeros((0, 3))
        """(F, 3) the frontier voxel centres of the last evaluation (the columns of ``last_seen``)."""
        self.last_occluders: NDArray[np.float64] = np.zeros((0, 3))
        """(N, 3) the occupied voxel centres that hid them."""
        self.last_intrinsics: Intrinsics | None = None
        self._projection: ProjectionEvaluator | None = None
        self.last_move_seconds: dict[int, float] = {}
        """The move seconds from the current state of every view the last :meth:`choose` timed (inf: unreachable)."""

    @property
    def lazy_reach(self) -> bool:
        """Whether the plan skips its reachability pass over every candidate (``tour.lazy_reach``): the views
        :meth:`choose` times are checked by their moves instead (inf: unreachable; :attr:`last_move_seconds`)."""
        return self.config.tour.lazy_reach

    def reset(self) -> None:
        """Stateless between plans: nothing to forget (but the projection score's fitters)."""
        if self._projection is not None:
            self._projection.reset()

    def evaluate(self, ctx: EvaluationContext) -> Evaluation:
        t0 = time.perf_counter()
        cfg: TourConfig = self.config.tour
        if cfg.score == "projection":
            if self._projection is None:
                self._projection = ProjectionEvaluator(self.config)
            return self._projection.evaluate(ctx)
        return self.frontier_visibility(ctx, t0)

    def frontier_visibility(self, ctx: EvaluationContext, t0: float) -> Evaluation:
        """Scores by the frontier voxels each eligible candidate sees (:func:`visible_frontier`, ``tour.width`` x
        ``tour.height``, ``tour.depth_tolerance_voxels``); keeps ``last_seen`` and the voxels and camera it was made
        with (``last_frontier``, ``last_occluders``, ``last_intrinsics``: what a path's frames are tested against).
        t0: ``time.perf_counter()`` when the evaluation started (its "score" timing)."""
        cfg: TourConfig = self.config.tour
        ctx.progress("visibility", 0, len(ctx.candidates))
        eligible = np.asarray(ctx.eligible, dtype=bool)
        frontier = ctx.voxel_map.centers(VoxelClass.FRONTIER)
        occupied = ctx.voxel_map.centers(VoxelClass.OCCUPIED)
        idx = np.flatnonzero(eligible)
        seen = np.zeros((len(ctx.candidates), len(frontier)), dtype=bool)
        tolerance = cfg.depth_tolerance_voxels * self.config.voxel.resolution
        poses = [ctx.candidates[int(i)].T_world_camera for i in idx]
        seen[idx] = visible_frontier(frontier, occupied, poses, ctx.intrinsics, cfg.width, cfg.height, tolerance)
        self.last_seen = seen
        self.last_frontier, self.last_occluders, self.last_intrinsics = frontier, occupied, ctx.intrinsics
        values = seen.sum(axis=1).astype(np.float64)
        from planner.baselines.evaluators import gain_scores

        scores = gain_scores(values, eligible)
        return Evaluation(scores, timings={"score": time.perf_counter() - t0})

    def choose(
        self,
        scores: Sequence[ViewScore],
        candidates: Sequence[Candidate],
        start: Pose,
        move_times: MoveTimes | None,
        *,
        taken: Sequence[Pose] = (),
        center: NDArray[np.float64] | None = None,
        move_paths: MovePaths | None = None,
    ) -> tuple[int | None, TourPlan | None]:
        """(the next view, the tour) from the last :meth:`evaluate`: the cover of its frontier, ordered by move
        time from the current state (``start``: the last view, for the straight-line fallback without
        ``move_times``). (None, None) when no view is eligible; without any frontier to cover, the eligible view
        with the largest score and no tour. With ``tour.opening = "ring"``, in the scan's first plans, the ring's
        next view first (:meth:`_choose_ring`; ``taken``: the views taken so far, ``T_world_camera``, the scan's
        first one first; ``center`` (3,): the object's box centre the candidates are about).
        move_paths: the cell's estimate of the camera's path on a move from here (:data:`planner.paths.MovePaths`,
        given when the cell captures during moves); with ``tour.path_coverage`` the cover counts, for the views
        whose paths are estimated (:func:`planner.paths.path_pool`), the frontier their move from here sees too
        (:meth:`_with_paths`)."""
        cfg: TourConfig = self.config.tour
        eligible = np.array([s.eligible for s in scores], dtype=bool)
        if not np.any(eligible):
            return None, None
        if cfg.score == "projection":
            return self._choose_near_best(scores, candidates, start, move_times)
        self.last_move_seconds = {}
        if cfg.opening == "ring" and center is not None and 1 <= len(taken) <= 2:
            best, plan = self._choose_ring(eligible, candidates, start, move_times, taken, center)
            if best is not None:
                return best, plan
        allowed = low_views(eligible, self.last_seen, candidates, cfg.cover_max_elevation_deg)
        seen = self.last_seen
        if move_paths is not None and cfg.path_coverage:
            seen = self._with_paths(allowed, candidates, move_paths)
        if self.lazy_reach:  # a ring view the cell cannot reach from here is no view for the cover either
            allowed[[v for v, t in self.last_move_seconds.items() if not math.isfinite(t)]] = False
        while True:  # with lazy_reach: a view of the cover the cell cannot reach is left out and the cover made again
            views, gains = greedy_cover(seen, allowed, cfg.horizon, cfg.min_gain)
            if not views:  # nothing gains: the best score among the views not known to be unreachable
                left = [s for s in scores if s.eligible and allowed[s.index]]
                if not left:
                    return None, None
                return int(max(left, key=lambda s: (s.score, -s.index)).index), None
            if move_times is not None:
                times = np.asarray(move_times(candidates, views), dtype=np.float64)
            else:
                times = straight_move_times(start, [candidates[i].T_world_camera for i in views])
            self.last_move_seconds.update((v, float(times[0, k + 1])) for k, v in enumerate(views))
            unreachable = [v for k, v in enumerate(views) if not math.isfinite(times[0, k + 1])]
            if not unreachable or not self.lazy_reach:
                break
            allowed[unreachable] = False
        reachable = [k for k in range(len(views)) if math.isfinite(times[0, k + 1])]
        if not reachable:
            return views[0], None
        keep = [0, *(k + 1 for k in reachable)]
        times = times[np.ix_(keep, keep)]
        times = np.where(np.isfinite(times), times, UNKNOWN_MOVE)  # a move between two views the cell did not time
        views = [views[k] for k in reachable]
        gains = [gains[k] for k in reachable]
        if cfg.order == "rate":
            head = min(len(views), MAX_EXACT) + 1  # the cover's first (largest-gain) views
            first = rate_order(times[:head, :head], gains[: head - 1], cfg.overhead_seconds)[0]
        else:
            first = 1 + int(np.argmax(gains)) if cfg.order == "gain" else None
        order, method = tour_order(times, first)  # the rest in the shortest order from the first
        states = [0, *order]
        cumulative = np.cumsum([times[a, b] for a, b in itertools.pairwise(states)])
        plan = TourPlan(
            views=tuple(views[i - 1] for i in order),
            gains=tuple(gains[i - 1] for i in order),
            seconds=tuple(float(s) for s in cumulative),
            method=method,
        )
        return plan.views[0], plan

    def _with_paths(
        self, allowed: NDArray[np.bool_], candidates: Sequence[Candidate], move_paths: MovePaths
    ) -> NDArray[np.bool_]:
        """(C, F) ``last_seen`` with, for each view of the pool of the ``allowed`` (C,) views
        (:func:`path_pool`, ``path.candidates`` and ``path.sweep_views``), the frontier the frames of its
        move from here see too (``path.sample_hz``). Only the first move of a tour starts here, but only the first
        runs before the next plan (the receding horizon), and the cover's first view is the one the path decides. A
        pool view the cell cannot reach is timed inf (``last_move_seconds``: with ``lazy_reach`` it leaves the
        cover)."""
        path = self.config.path
        seen = self.last_seen.copy()
        counts = seen.sum(axis=1).astype(np.float64)
        pool = path_pool(counts, allowed, candidates, path.candidates, path.sweep_views)
        if not pool or seen.shape[1] == 0 or self.last_intrinsics is None:
            return seen
        paths = move_paths(candidates, pool, path.sample_hz)
        known = [(v, p) for v, p in zip(pool, paths, strict=True) if p is not None]
        self.last_move_seconds.update((v, math.inf) for v, p in zip(pool, paths, strict=True) if p is None)
        cfg = self.config.tour
        tolerance = cfg.depth_tolerance_voxels * self.config.voxel.resolution
        frames = frames_seen(
            self.last_frontier,
            self.last_occluders,
            [p for _, p in known],
            self.last_intrinsics,
            cfg.width,
            cfg.height,
            tolerance,
        )
        start = 0
        for v, p in known:
            seen[v] |= frames[start : start + len(p)].any(axis=0)
            start += len(p)
        return seen

    def _choose_ring(
        self,
        eligible: NDArray[np.bool_],
        candidates: Sequence[Candidate],
        start: Pose,
        move_times: MoveTimes | None,
        taken: Sequence[Pose],
        center: NDArray[np.float64],
    ) -> tuple[int | None, TourPlan | None]:
        """The ring's next view (:func:`ring_view`) and a one-view tour (method "ring"); (None, None) when the ring
        is closed or none of its views is eligible and reachable (the tour then plans as without an opening)."""
        cfg: TourConfig = self.config.tour
        tolerance = math.radians(cfg.ring_tolerance_deg)
        first = azimuth_of(taken[0].translation, center)
        directions = ring_directions(
            first,
            math.radians(cfg.ring_spread_deg),
            [azimuth_of(p.translation, center) for p in taken[1:]],
            tolerance,
        )
        if not directions or not candidates:
            return None, None
        counts = self.last_seen.sum(axis=1).astype(np.float64)
        azimuths = np.array([c.azimuth for c in candidates])
        elevations = np.array([c.elevation for c in candidates])
        best, timed = ring_view(
            counts,
            eligible,
            azimuths,
            elevations,
            directions,
            math.radians(cfg.ring_max_elevation_deg),
            tolerance,
            cfg.ring_share,
            seconds_from_here(move_times, candidates, start),
            cfg.near_views,
        )
        self.last_move_seconds.update(timed)
        if best is None:
            return None, None
        then: tuple[int, ...] = ()
        if cfg.lookahead and len(directions) == 2:  # the other side opens the next plan: the move here plans for it
            side = int(np.argmin([float(azimuth_gap(azimuths[best], d)) for d in directions]))
            then = other_side(
                counts,
                azimuths,
                elevations,
                directions[1 - side],
                math.radians(cfg.ring_max_elevation_deg),
                tolerance,
                cfg.ring_share,
                cfg.near_views,
            )
        plan = TourPlan(views=(best,), gains=(int(counts[best]),), seconds=(timed[best],), method="ring", then=then)
        return best, plan

    def _choose_near_best(
        self, scores: Sequence[ViewScore], candidates: Sequence[Candidate], start: Pose, move_times: MoveTimes | None
    ) -> tuple[int | None, TourPlan | None]:
        """:meth:`choose` with ``tour.score = "projection"``: :func:`near_best` under the cell's exact moves from
        the current state (without ``move_times``: the best F, as ``projection``)."""
        cfg: TourConfig = self.config.tour
        ranked = [
            (s.index, s.score) for s in sorted((s for s in scores if s.eligible), key=lambda s: (-s.score, s.index))
        ]
        self.last_move_seconds = {}
        if move_times is None:
            return ranked[0][0], None
        seconds = seconds_from_here(move_times, candidates, start)
        best, self.last_move_seconds = near_best(ranked, seconds, cfg.slack, cfg.near_views)
        if best is None:
            return None, None
        return best, TourPlan(views=(best,), gains=(0,), seconds=(self.last_move_seconds[best],), method="near")


EVALUATORS["tour"] = TourEvaluator


def path_pool(
    counts: NDArray[np.float64],
    eligible: NDArray[np.bool_],
    candidates: Sequence[Candidate],
    top: int,
    sweep_views: int,
) -> list[int]:
    """The candidates whose moves a plan estimates, in increasing index order: the ``top`` eligible ones that see the
    most frontier (``counts`` (C,), those seeing none left out; the lower index on a tie) and up to ``sweep_views``
    eligible views of the lowest parallel among the eligible, spread evenly over its azimuths (the first of each
    share in azimuth order). eligible: (C,) bool."""
    eligible = np.asarray(eligible, dtype=bool)
    counts = np.asarray(counts, dtype=np.float64)
    idx = np.flatnonzero(eligible & (counts > 0))
    ranked = idx[np.lexsort((idx, -counts[idx]))][:top]
    chosen = {int(i) for i in ranked}
    ok = np.flatnonzero(eligible)
    if sweep_views > 0 and len(ok) and len(candidates) == len(eligible):
        low = min(candidates[int(i)].parallel for i in ok)
        ring = sorted((int(i) for i in ok if candidates[int(i)].parallel == low), key=lambda i: candidates[i].azimuth)
        step = max(1, math.ceil(len(ring) / sweep_views))
        chosen.update(ring[::step][:sweep_views])
    return sorted(chosen)


def frames_seen(
    frontier: NDArray[np.float64],
    occluders: NDArray[np.float64],
    paths: Sequence[CameraPath],
    intrinsics: Intrinsics,
    width: int,
    height: int,
    tolerance: float,
) -> NDArray[np.bool_]:
    """(S, F) bool: frontier voxel f seen from frame s of ``paths`` (all their frames, in order), by the tour's
    visibility test (:func:`visible_frontier`: ``width`` x ``height`` raster, ``tolerance`` metres)."""
    poses = [p for path in paths for p in path.poses()]
    return visible_frontier(frontier, occluders, poses, intrinsics, width, height, tolerance)
