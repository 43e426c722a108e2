"""The ``path`` planner: the next view chosen for what its move sees on the way and what the move costs (not in the
paper: with a camera that captures while the cell moves, every move is a series of views).

A cell that captures frames during its moves (``--move-capture HZ``) sees the object all along a move: while the plate
turns the camera sweeps a ring about the object, and one revolution at the lowest parallel covers nearly all of the
reachable surface (docs/experiments/scan-while-moving.md). A planner that scores the view alone misses that, and a
view can be worth going to for the path that reaches it. Each plan here:

1. **Visibility of the views** (as the ``tour`` planner, :func:`planner.tour.visible_frontier`): which frontier
   voxels each eligible candidate sees.
2. **Paths** (:func:`path_pool`): the candidates whose moves are estimated: the ``path.candidates`` that see the
   most frontier, and the sweep views, eligible views of the lowest parallel spread around the object
   (``path.sweep_views``): their moves turn the plate with the camera low, the move that sees the most.
   The cell estimates each move from the current state (:data:`MovePaths`: the camera poses at
   ``path.sample_hz`` along it and its seconds; the planner never sees the arm).
3. **Path gain** (:func:`path_gains`): the frontier voxels the view *or any frame along its move* sees, and a sample
   of the unknown voxels they see (:func:`unknown_sample`, ``path.unknown_stride``: after the first view the frontier
   is a thin rim, and the unknown space a sweep looks into tells a long sweep past the unseen side from a short
   move), each voxel counted once however many frames see it (overlapping frames add nothing twice).
4. **Rate** (:func:`path_rates`): gain / (move seconds + ``path.overhead_seconds``): frontier per second of robot
   time. The next view is the one with the highest rate.

Without paths from the cell (capture off, or a cell that does not know where its camera is), the path gain is the
view's own, and the rule is the view's frontier per second of its move.
"""

from __future__ import annotations

import math
import time
from collections.abc import Sequence
from typing import TYPE_CHECKING

import numpy as np
from numpy.typing import NDArray

from planner.config import PathConfig, PlannerConfig
from planner.evaluators import EVALUATORS
from planner.tour import TourEvaluator, frames_seen, path_pool, straight_move_times, visible_frontier
from planner.types import CameraPath, Candidate, MovePaths, Pose, TourPlan, ViewScore, VoxelClass
from planner.voxel_map import VoxelMap

if TYPE_CHECKING:
    from planner.evaluators import Evaluation, EvaluationContext
    from planner.tour import MoveTimes


def path_gains(
    seen_views: NDArray[np.bool_], seen_frames: NDArray[np.bool_], frames_per_path: Sequence[int]
) -> NDArray[np.int64]:
    """(K,) the frontier voxels the K views or any frame along each one's move sees, each voxel once.

    seen_views: (K, F) bool, voxel f seen from view k. seen_frames: (S, F) bool, the frames of all K paths in order
    (path k's ``frames_per_path[k]`` frames follow path k - 1's), as :func:`planner.tour.visible_frontier` gives.
    """
    seen_views = np.asarray(seen_views, dtype=bool)
    union = seen_views.copy()
    counts = np.asarray(frames_per_path, dtype=np.int64)
    if len(counts) != len(seen_views):
        raise ValueError(f"frames_per_path: one count per view ({len(seen_views)}), got {len(counts)}")
    if int(counts.sum()) != len(seen_frames):
        raise ValueError(f"seen_frames: {int(counts.sum())} rows expected, got {len(seen_frames)}")
    starts = np.concatenate([[0], np.cumsum(counts)[:-1]])
    for k in np.flatnonzero(counts):
        union[k] |= np.asarray(seen_frames[starts[k] : starts[k] + counts[k]], dtype=bool).any(axis=0)
    return union.sum(axis=1).astype(np.int64)


def path_rates(gains: NDArray[np.float64], seconds: NDArray[np.float64], overhead: float) -> NDArray[np.float64]:
    """(K,) frontier voxels per second of robot time: gains (K,) / (seconds (K,) + overhead); -inf for a move that
    cannot be made (seconds inf or nan)."""
    gains = np.asarray(gains, dtype=np.float64)
    seconds = np.asarray(seconds, dtype=np.float64)
    ok = np.isfinite(seconds)
    out = np.full(len(gains), -math.inf)
    out[ok] = gains[ok] / np.maximum(seconds[ok] + overhead, 1e-9)
    return out


def unknown_sample(voxel_map: VoxelMap, stride: int, resolution: float) -> NDArray[np.float64]:
    """(U, 3) world centres of the UNKNOWN voxels of ``voxel_map`` (edge ``resolution``) whose lattice indices are
    multiples of ``stride`` in every axis (one in ``stride**3``); empty for stride 0 or before the first frame."""
    centers = np.asarray(voxel_map.centers(VoxelClass.UNKNOWN), dtype=np.float64).reshape(-1, 3)
    if stride <= 0 or len(centers) == 0:
        return np.zeros((0, 3))
    idx = np.floor(centers / resolution).astype(np.int64)
    return centers[np.all(idx % stride == 0, axis=1)]


class PathEvaluator(TourEvaluator):
    """Scores each candidate by the frontier it sees (as ``tour``) and chooses the move with the most frontier per
    second, counting what the frames along the move see (module docstring)."""

    name = "path"
    stages = ("visibility", "paths")

    def __init__(self, config: PlannerConfig) -> None:
        super().__init__(config)
        self.last_paths: dict[int, CameraPath] = {}
        """The estimated path of every move the last :meth:`choose` weighed (candidate index -> path)."""
        self.last_rates: dict[int, float] = {}
        """Frontier voxels per second of every reachable move the last :meth:`choose` weighed."""
        self.last_gains: dict[int, int] = {}
        """The path gain (:func:`path_gains`) of every move the last :meth:`choose` weighed."""
        self.last_unknown: NDArray[np.float64] = np.zeros((0, 3))
        """(U, 3) the unknown voxel centres the last :meth:`evaluate` sampled (``path.unknown_stride``)."""

    def evaluate(self, ctx: EvaluationContext) -> Evaluation:
        """The tour's frontier visibility (``tour.width``, ``tour.height``, ``tour.depth_tolerance_voxels``), whatever
        ``tour.score`` says, and the sample of unknown voxels the path gain counts too (:func:`unknown_sample`)."""
        evaluation = self.frontier_visibility(ctx, time.perf_counter())
        self.last_unknown = unknown_sample(ctx.voxel_map, self.config.path.unknown_stride, self.config.voxel.resolution)
        return evaluation

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
        """(the next view, a one-view plan, method "path") from the last :meth:`evaluate`: of the pool
        (:func:`path_pool`), the reachable view with the most frontier per second (:func:`path_rates`), counting
        what the frames along its move see (:func:`path_gains`) when ``move_paths`` is given, else the view alone
        timed by ``move_times`` (straight lines from ``start`` without it). (None, None) when no view is eligible
        or none of the pool is reachable; without frontier anywhere, the eligible view with the largest score
        (no pool) or the quickest reachable move. ``taken``, ``center``: unused (the tour's signature)."""
        cfg: PathConfig = self.config.path
        eligible = np.array([s.eligible for s in scores], dtype=bool)
        self.last_move_seconds, self.last_paths, self.last_rates, self.last_gains = {}, {}, {}, {}
        if not np.any(eligible):
            return None, None
        seen = self.last_seen
        if seen.shape != (len(scores), len(self.last_frontier)):
            seen = np.zeros((len(scores), len(self.last_frontier)), dtype=bool)
        counts = seen.sum(axis=1).astype(np.float64)
        pool = path_pool(counts, eligible, candidates, cfg.candidates, cfg.sweep_views)
        if not pool:  # no frontier seen and no sweep view: the best score, as the tour
            best = max((s for s in scores if s.eligible), key=lambda s: (s.score, -s.index))
            return int(best.index), None
        tour = self.config.tour
        tolerance = tour.depth_tolerance_voxels * self.config.voxel.resolution
        unknown = self.last_unknown if self.last_intrinsics is not None else np.zeros((0, 3))
        views_seen = seen[pool]
        if len(unknown):  # what of the unknown space each view of the pool sees
            assert self.last_intrinsics is not None
            poses = [candidates[i].T_world_camera for i in pool]
            views_unknown = visible_frontier(
                unknown, self.last_occluders, poses, self.last_intrinsics, tour.width, tour.height, tolerance
            )
            views_seen = np.concatenate([views_seen, views_unknown], axis=1)
        gains = views_seen.sum(axis=1).astype(np.int64)
        if move_paths is not None:
            paths = move_paths(candidates, pool, cfg.sample_hz)
            if len(paths) != len(pool):
                raise ValueError(f"move_paths: {len(pool)} paths expected, got {len(paths)}")
            seconds = np.array([math.inf if p is None else p.seconds for p in paths])
            known = [k for k, p in enumerate(paths) if p is not None]
            self.last_paths = {pool[k]: p for k, p in enumerate(paths) if p is not None}
            if known and len(self.last_frontier) + len(unknown) and self.last_intrinsics is not None:
                chosen = [p for p in paths if p is not None]
                frames = frames_seen(
                    np.concatenate([self.last_frontier.reshape(-1, 3), unknown]),
                    self.last_occluders,
                    chosen,
                    self.last_intrinsics,
                    tour.width,
                    tour.height,
                    tolerance,
                )
                gains[known] = path_gains(views_seen[known], frames, [len(p) for p in chosen])
        elif move_times is not None:
            seconds = np.asarray(move_times(candidates, pool), dtype=np.float64)[0, 1:]
        else:
            seconds = straight_move_times(start, [candidates[i].T_world_camera for i in pool])[0, 1:]
        rates = path_rates(gains.astype(np.float64), seconds, cfg.overhead_seconds)
        self.last_move_seconds = {c: float(s) for c, s in zip(pool, seconds, strict=True)}
        self.last_gains = {c: int(g) for c, g in zip(pool, gains, strict=True)}
        self.last_rates = {c: float(r) for c, r in zip(pool, rates, strict=True) if math.isfinite(r)}
        if not self.last_rates:
            return None, None
        if max(self.last_rates.values()) <= 0:  # nothing to gain anywhere: the quickest reachable move
            best = min(self.last_rates, key=lambda c: (self.last_move_seconds[c], c))
        else:
            best = max(self.last_rates, key=lambda c: (self.last_rates[c], -c))
        plan = TourPlan(
            views=(best,), gains=(self.last_gains[best],), seconds=(self.last_move_seconds[best],), method="path"
        )
        return best, plan


EVALUATORS["path"] = PathEvaluator
