"""Algorithm 1 of the paper as a stateful object: frames in, next views out.

One loop of the scan::

    report = planner.integrate(frame)   # Preprocess, register (ICP), VoxelStructConstruct
    plan = planner.plan(reachable)      # EllipsoidsFit, ProposeCandidateViewpoints,
                                        # InValidPartition, QualityEvaluate, SelectNBV

The planner never talks to a device. ``integrate`` either succeeds or raises
``ValueError`` and leaves every piece of state as it was.
"""

from __future__ import annotations

import dataclasses
import math
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, cast

import numpy as np
from numpy.typing import NDArray

from planner.candidates import candidates_from_poses, held_aim, propose_candidates
from planner.cloud import merge_cloud
from planner.clustering import single_thread_blas
from planner.config import PlannerConfig
from planner.evaluators import Evaluation, EvaluationContext, ViewEvaluator, make_evaluator
from planner.noise import (
    dropouts_filled,
    plane_moved,
    plate_heights,
    plate_plane,
    registration_for,
    unknown_beyond_range,
    without_flying_pixels,
)
from planner.partitions import (
    azimuth_of,
    default_tolerance,
    eligible_sectors,
    not_taken,
    sector_edges,
    sector_of,
    select_with_move_cost,
)
from planner.partitions import select_best as select_best_view
from planner.preprocess import preprocess_frame
from planner.progress import ProgressFn, Stages
from planner.registration import RegistrationResult, register
from planner.types import BoundingBox, Candidate, DepthFrame, Intrinsics, PlanResult, Pose, TourPlan, VoxelClass
from planner.voxel_map import VoxelMap

if TYPE_CHECKING:
    from planner.paths import MovePaths

ChooseFn = Callable[..., tuple[int | None, TourPlan | None]]
"""An evaluator's own choice (``planner.tour.TourEvaluator.choose``): (scores, candidates, the last view, move_times,
taken=the views taken, center=the candidates' centre[, move_paths=the cell's path estimate]) -> (the next view, the
predicted tour)."""


@dataclass(frozen=True)
class IntegrationReport:
    """What one ``Planner.integrate`` did.

    growth: relative growth of the accumulated point count (None on the first frame).
    timings: seconds for "preprocess", "register" and "integrate".
    """

    iteration: int
    n_points_frame: int
    n_points_total: int
    growth: float | None
    registration: RegistrationResult | None
    T_world_camera: Pose
    timings: dict[str, float] = field(default_factory=dict)


class Planner:
    """The projection-based NBV planner (or a baseline evaluator in its place)."""

    def __init__(self, config: PlannerConfig | None = None, evaluator: str = "projection") -> None:
        self.config = config or PlannerConfig()
        self.evaluator: ViewEvaluator = make_evaluator(evaluator, self.config)
        self.voxel_map = VoxelMap(self.config.voxel)
        self.views: list[Pose] = []
        self.cloud: NDArray[np.float64] = np.zeros((0, 3))
        self.cloud_from_move: NDArray[np.bool_] = np.zeros(0, dtype=bool)
        """(K,) the points of ``cloud`` only frames taken during moves measured (:func:`planner.cloud.merge_cloud`)."""
        self.point_counts: list[int] = []
        self.intrinsics: Intrinsics | None = None
        self.last_plan: PlanResult | None = None
        self._rng = np.random.default_rng(self.config.cluster.seed)
        self._aim: BoundingBox | None = None
        """With ``candidates.aim = "content"``: the box the candidates are built about, held after each frame
        (:func:`planner.candidates.held_aim`)."""

    @property
    def iteration(self) -> int:
        """Frames integrated so far."""
        return len(self.views)

    @property
    def terminated(self) -> str | None:
        """Why Algorithm 1 stops now: "max_views", "no_frontier", "growth", or None."""
        term = self.config.termination
        if self.iteration >= term.max_views:
            return "max_views"
        if self.iteration == 0:
            return None
        if term.stop_without_frontier and self.voxel_map.count(VoxelClass.FRONTIER) == 0:
            return "no_frontier"
        if term.growth_threshold > 0 and len(self.point_counts) >= 2:
            prev, cur = self.point_counts[-2], self.point_counts[-1]
            if prev > 0 and (cur - prev) / prev < term.growth_threshold:
                return "growth"
        return None

    # ------------------------------------------------------------------ integrate

    def integrate(self, frame: DepthFrame, *, move_frame: bool = False, registered: bool = False) -> IntegrationReport:
        """Preprocess, register and integrate one frame.

        move_frame: the frame was taken while the cell moved between views (capture during moves): it goes into the
        map and the cloud like a view's, but it is no view (``views``, ``iteration`` and the per-view point counts
        stay; the next view's growth counts its points).
        registered: refuse the frame (ValueError, state unchanged) when registration ran and did not accept it (a
        move frame is worth its pose only when ICP confirmed it).
        Raises ValueError (state unchanged) for an empty frame, a frame with no
        point on the object after preprocessing, or intrinsics that differ from
        the first frame's. BLAS runs on one thread meanwhile (:func:`planner.clustering.single_thread_blas`: the
        same results, half the CPU; the other core stays with the server and the other sessions).
        """
        with single_thread_blas():
            return self._integrate(frame, move_frame, registered)

    def _integrate(self, frame: DepthFrame, move_frame: bool = False, registered: bool = False) -> IntegrationReport:
        if not isinstance(frame, DepthFrame):
            raise ValueError(f"frame: expected a DepthFrame, got {type(frame).__name__}")
        if self.intrinsics is not None and frame.intrinsics != self.intrinsics:
            raise ValueError("frame: intrinsics differ from the first frame's")
        if not np.any(frame.valid):
            raise ValueError("empty frame: the depth image has no returns")
        timings: dict[str, float] = {}

        t0 = time.perf_counter()
        frame = without_flying_pixels(frame, self.config.noise.flying_jump)
        plane = plate_plane(frame, self.config.preprocess, self.config.noise)  # from measured depths only
        plate = plate_heights(frame, self.config.preprocess, self.config.noise, plane)
        points, dense = preprocess_frame(frame.points_world, self.voxel_map.bbox, self.config.preprocess, plate)
        timings["preprocess"] = time.perf_counter() - t0
        if len(points) == 0:
            raise ValueError("empty frame: no point left on the object after cropping and plate removal")

        t0 = time.perf_counter()
        registration: RegistrationResult | None = None
        if self.config.registration.enabled and len(self.cloud) > 0:
            gates = registration_for(frame, self.config.registration, self.config.noise)
            registration = register(points, self.cloud, gates)
            if registration.accepted:
                frame = frame.with_pose(registration.correction @ frame.T_world_camera)
                points = registration.correction.apply(points)
                dense = registration.correction.apply(dense)
                plane = plane_moved(plane, registration.correction)
            elif registered:
                raise ValueError(f"registration not accepted: {registration.reason}")
        timings["register"] = time.perf_counter() - t0

        t0 = time.perf_counter()
        # every point of the kept cells marks OCCUPIED (a voxel the surface only clips may hold no centroid)
        if self.config.noise.dropout_fill_px > 0:  # dropouts are unknown, not free; the plate's pixels stay free
            filled = dropouts_filled(frame, self.config.noise.dropout_fill_px)
            carve = self._plate_as_free_space(
                filled, plate_heights(filled, self.config.preprocess, self.config.noise, plane)
            )
        else:
            if registration is not None and registration.accepted:  # the moved points against the moved plane
                plate = plate_heights(frame, self.config.preprocess, self.config.noise, plane)
            carve = self._plate_as_free_space(frame, plate)
        carve = unknown_beyond_range(carve, frame, self.config.candidates.max_range)
        self.voxel_map.integrate(carve, dense)  # atomic: raises before changing anything
        if self.config.candidates.aim == "content":
            voxels = self.config.candidates.aim_hold_voxels  # faces lie on the voxel grid: half a voxel of slack
            hold = (voxels + 0.5) * self.voxel_map.resolution if voxels > 0 else 0.0
            self._aim = held_aim(self._aim, self._content_box(), hold)
        timings["integrate"] = time.perf_counter() - t0

        pre = self.config.preprocess
        self.cloud, self.cloud_from_move = merge_cloud(
            self.cloud, self._from_move(), points, move_frame, pre.downsample, pre.move_point_radius
        )
        growth = None
        if self.point_counts:
            prev = self.point_counts[-1]
            growth = (len(self.cloud) - prev) / prev if prev > 0 else None
        self.intrinsics = frame.intrinsics
        if not move_frame:
            self.point_counts.append(len(self.cloud))
            self.views.append(frame.T_world_camera)
        return IntegrationReport(
            iteration=self.iteration,
            n_points_frame=len(points),
            n_points_total=len(self.cloud),
            growth=growth,
            registration=registration,
            T_world_camera=frame.T_world_camera,
            timings=timings,
        )

    def _from_move(self) -> NDArray[np.bool_]:
        """(K,) ``cloud_from_move``, all False for a planner pickled before it existed or a cloud set directly."""
        flags = getattr(self, "cloud_from_move", None)
        if flags is None or len(flags) != len(self.cloud):
            return np.zeros(len(self.cloud), dtype=bool)
        return flags

    def _plate_as_free_space(self, frame: DepthFrame, plate: NDArray[np.float64] | None = None) -> DepthFrame:
        """The frame as the voxel map should carve it: pixels that hit the plate count as "no return".

        The plate is known geometry, not object: a ray that ends on it crossed free space all the way
        down, and everything under the plate is below B's floor. plate: (N,) the band of each point of
        ``frame.points_world`` (:func:`planner.noise.plate_heights`; None: computed here). Without this, the voxels where such
        rays end (the layer resting on the plate) become UNKNOWN, and those next to the object's base
        stay FRONTIER for ever: no view can ever clear them, and the planner keeps looking at them.
        """
        if not self.config.voxel.floor:
            return frame
        if plate is None:
            plate = plate_heights(frame, self.config.preprocess, self.config.noise)
        v, u = frame.pixels  # the order of frame.points_world
        on_plate = frame.points_world[:, 2] < self.config.voxel.floor_height + plate
        if not np.any(on_plate):
            return frame
        depth = frame.depth.copy()
        depth[v[on_plate], u[on_plate]] = 0.0
        return DepthFrame(depth, frame.T_world_camera, frame.intrinsics)

    # ------------------------------------------------------------------ plan

    def candidate_box(self) -> BoundingBox:
        """The box the candidate sphere is built about (``candidates.aim``): B, or the box of the OCCUPIED and
        FRONTIER voxels (B when there are none) as held after the last frame (``candidates.aim_hold_voxels``).
        ValueError before the first frame."""
        bbox = self.voxel_map.bbox
        if bbox is None:
            raise ValueError("candidate_box: no frame has been integrated yet")
        if self.config.candidates.aim == "bbox":
            return bbox
        return self._aim if self._aim is not None else self._content_box()

    def _content_box(self) -> BoundingBox:
        """The box of the OCCUPIED and FRONTIER voxels now (B when there are none; the map has a frame)."""
        bbox = self.voxel_map.bbox
        assert bbox is not None
        classes = self.voxel_map.classes
        idx = np.argwhere((classes == VoxelClass.OCCUPIED) | (classes == VoxelClass.FRONTIER))
        if len(idx) == 0:
            return bbox
        res = self.voxel_map.resolution
        origin = self.voxel_map.origin
        return BoundingBox(origin + idx.min(axis=0) * res, origin + (idx.max(axis=0) + 1) * res)

    def _not_revisited(
        self, candidates: Sequence[Candidate], center: NDArray[np.float64], allowed: NDArray[np.bool_]
    ) -> NDArray[np.bool_]:
        """(C,) bool: candidates outside ``partitions.revisit_deg`` of every view taken.

        The radius is never below half the candidate spacing (the view itself). If the
        wider radius would leave none of the ``allowed`` (C,) candidates, only the half
        spacing applies, so a long scan keeps going rather than running out of views.
        """
        spacing = default_tolerance(candidates, center)
        wide = max(spacing, math.radians(self.config.partitions.revisit_deg))
        fresh = not_taken(candidates, self.views, wide, center=center)
        if wide > spacing and not np.any(fresh & allowed):
            fresh = not_taken(candidates, self.views, spacing, center=center)
        return fresh

    def _not_given_taken(self, candidates: Sequence[Candidate]) -> NDArray[np.bool_]:
        """(C,) bool: given candidates no view taken stands at (each view taken rules out its nearest candidate)."""
        fresh = np.ones(len(candidates), dtype=bool)
        positions = np.array([c.position for c in candidates])
        for view in self.views:
            fresh[int(np.argmin(np.linalg.norm(positions - view.translation, axis=1)))] = False
        return fresh

    def plan(
        self,
        reachable: Callable[[Pose], bool] | None = None,
        move_cost: Callable[[Sequence[Candidate], NDArray[np.bool_]], NDArray[np.float64]] | None = None,
        progress: ProgressFn | None = None,
        move_times: Callable[[Sequence[Candidate], Sequence[int]], NDArray[np.float64]] | None = None,
        candidate_poses: Sequence[Pose] | None = None,
        move_paths: MovePaths | None = None,
    ) -> PlanResult:
        """Score every candidate and pick the next best view.

        reachable: the cell's check; unreachable candidates are ineligible. An evaluator with ``lazy_reach`` (the
        ``tour`` planner, ``tour.lazy_reach``) skips it when ``move_times`` is given: the views it times are
        checked by their move times (inf: ineligible, "unreachable"), the others stay unchecked.
        move_cost: (candidates, eligible (C,) bool) -> (C,) seconds each move would take (inf = unknown), from
        the caller (the planner never sees the arm); asked only when ``selection.move_cost_weight`` > 0, and
        then the choice trades F against it (:func:`planner.partitions.select_with_move_cost`). With the ``tour``
        planner ``PlanResult.move_costs`` comes from ``move_times`` instead.
        move_times: (candidates, K indices) -> (K + 1, K + 1) seconds between the current state and those views
        (:data:`planner.tour.MoveTimes`): what an evaluator that chooses by itself (``tour``) orders its views by;
        without it, straight lines at a nominal speed.
        progress: called with a :class:`planner.progress.PlanProgress` at each stage (candidates,
        reachability, the evaluator's stages, move costs, select) and as its items are done.
        candidate_poses: the views to choose among instead of the hemisphere (a recorded set's,
        :func:`planner.candidates.candidates_from_poses`): each view taken rules out the given view nearest it
        (a registered pose is not the recorded one to the bit), and when the longitude partitions leave no view
        eligible the partitions are dropped (a few given views can leave a sector empty).
        move_paths: (candidates, K indices, hz) -> the camera's path on the move from the current state to each
        (:data:`planner.paths.MovePaths`), given when the cell captures frames during its moves: the ``path``
        planner counts what those frames see, and so does the ``tour`` (``tour.path_coverage``); the other planners
        ignore it.
        Raises ValueError before the first frame. BLAS runs on one thread meanwhile (as in :meth:`integrate`).
        """
        with single_thread_blas():
            return self._plan(reachable, move_cost, progress, move_times, candidate_poses, move_paths)

    def _plan(
        self,
        reachable: Callable[[Pose], bool] | None,
        move_cost: Callable[[Sequence[Candidate], NDArray[np.bool_]], NDArray[np.float64]] | None,
        progress: ProgressFn | None,
        move_times: Callable[[Sequence[Candidate], Sequence[int]], NDArray[np.float64]] | None,
        candidate_poses: Sequence[Pose] | None = None,
        move_paths: MovePaths | None = None,
    ) -> PlanResult:
        if self.iteration == 0 or self.voxel_map.bbox is None or self.intrinsics is None:
            raise ValueError("plan: no frame has been integrated yet; capture one first")
        cfg = self.config
        timings: dict[str, float] = {}
        weight = cfg.selection.move_cost_weight
        stages = Stages(
            [
                "candidates",
                *(["reachability"] if reachable is not None else []),
                *getattr(self.evaluator, "stages", ("evaluate",)),
                *(["move costs"] if weight > 0 and (move_cost is not None or move_times is not None) else []),
                "select",
            ],
            progress,
        )

        t0 = time.perf_counter()
        stages("candidates", 0, 1)
        bbox = self.voxel_map.bbox
        if candidate_poses is None:
            candidates, center, radius = propose_candidates(self.candidate_box(), cfg.candidates, cfg.partitions)
        else:
            candidates, center, radius = candidates_from_poses(candidate_poses, self.candidate_box(), cfg.partitions)
        timings["candidates"] = time.perf_counter() - t0

        t0 = time.perf_counter()
        view_sectors = [sector_of(azimuth_of(view.translation, center), cfg.partitions) for view in self.views]
        scanned = set(view_sectors)
        allowed = eligible_sectors(scanned, cfg.partitions.sectors)
        in_sector = np.array([c.sector in allowed for c in candidates], dtype=bool)
        reach = np.ones(len(candidates), dtype=bool)
        lazy = reachable is not None and move_times is not None and bool(getattr(self.evaluator, "lazy_reach", False))
        if reachable is not None and not lazy:
            for i, c in enumerate(candidates):
                stages("reachability", i, len(candidates))
                reach[i] = bool(reachable(c.T_world_camera))
        eligible = in_sector & reach
        if candidate_poses is None:
            fresh = self._not_revisited(candidates, center, eligible)
        else:
            fresh = self._not_given_taken(candidates)
            if not np.any(eligible & fresh):
                in_sector = np.ones(len(candidates), dtype=bool)
                eligible = reach.copy()
        eligible &= fresh
        reasons = ineligible_reasons(in_sector, reach, fresh)
        timings["select"] = time.perf_counter() - t0

        evaluation = self.evaluator.evaluate(
            EvaluationContext(self.voxel_map, candidates, self.intrinsics, eligible, self._rng, stages)
        )
        timings.update(evaluation.timings)

        t0 = time.perf_counter()
        move_costs = None
        tour = None
        choose = getattr(self.evaluator, "choose", None)
        if callable(choose):
            stages("tour", 0, 1)
            extra = {"move_paths": move_paths} if move_paths is not None else {}
            best, tour = cast(ChooseFn, choose)(
                evaluation.scores, candidates, self.views[-1], move_times, taken=self.views, center=center, **extra
            )
            timed: dict[int, float] = getattr(self.evaluator, "last_move_seconds", {})  # the views it timed itself
            if lazy:  # only the views it timed have a move (and a reachability answer: inf = unreachable)
                move_costs = np.full(len(candidates), math.inf)
                move_costs[list(timed)] = list(timed.values())
                evaluation, reasons = _unreachable_marked(evaluation, reasons, timed)
            elif move_times is not None:  # each eligible candidate's move from here, for the table
                move_costs = moves_from_here(move_times, candidates, [s.eligible for s in evaluation.scores])
                move_costs[list(timed)] = list(timed.values())  # the evaluator's own (exact) times win
            stages("select", 0, 1)
        elif weight > 0 and (move_times is not None or move_cost is not None):
            eligible_now = np.array([s.eligible for s in evaluation.scores], dtype=bool)
            stages("move costs", 0, int(eligible_now.sum()))
            if move_times is not None:  # the cell's cached estimates (no IK of their own)
                move_costs = moves_from_here(move_times, candidates, eligible_now)
            else:
                move_costs = np.asarray(move_cost(candidates, eligible_now), dtype=np.float64)  # type: ignore[misc]
            stages("select", 0, 1)
            best = select_with_move_cost(evaluation.scores, move_costs, weight)
        else:
            stages("select", 0, 1)
            best = select_best_view(evaluation.scores)
        timings["select"] += time.perf_counter() - t0

        plan = PlanResult(
            iteration=self.iteration,
            bbox=bbox,
            voxels=self.voxel_map.snapshot(),
            ellipsoids=evaluation.ellipsoids,
            fits=evaluation.fits,
            candidates=candidates,
            scores=evaluation.scores,
            best_index=best,
            hemisphere_center=center,
            hemisphere_radius=radius,
            sector_edges=sector_edges(cfg.partitions),
            scanned_sectors=frozenset(scanned),
            eligible_sectors=frozenset(allowed),
            timings=timings,
            terminated=self.terminated,
            move_costs=move_costs,
            ineligible_reasons=reasons,
            tour=tour,
        )
        self.last_plan = plan
        stages("select", 1, 1)
        return plan


def moves_from_here(
    move_times: Callable[[Sequence[Candidate], Sequence[int]], NDArray[np.float64]],
    candidates: Sequence[Candidate],
    eligible: Sequence[bool] | NDArray[np.bool_],
) -> NDArray[np.float64]:
    """(C,) seconds of the move from the current state to each eligible candidate (row 0 of ``move_times``), inf
    for the others."""
    idx = [int(i) for i in np.flatnonzero(np.asarray(eligible, dtype=bool))]
    out = np.full(len(candidates), math.inf)
    out[idx] = np.asarray(move_times(candidates, idx), dtype=np.float64)[0, 1:]
    return out


def _unreachable_marked(
    evaluation: Evaluation, reasons: tuple[str, ...], timed: dict[int, float]
) -> tuple[Evaluation, tuple[str, ...]]:
    """The evaluation and the reasons with every view whose timed move is inf made ineligible ("unreachable"): the
    reachability answers of an evaluator that asks them itself (``lazy_reach``)."""
    out = list(reasons)
    scores = list(evaluation.scores)
    for i, t in timed.items():
        if not math.isfinite(t):
            out[i] = "unreachable"
            scores[i] = dataclasses.replace(scores[i], eligible=False)
    return dataclasses.replace(evaluation, scores=tuple(scores)), tuple(out)


def ineligible_reasons(
    in_sector: NDArray[np.bool_], reach: NDArray[np.bool_], fresh: NDArray[np.bool_]
) -> tuple[str, ...]:
    """Why each candidate is not eligible, "" for an eligible one; the first rule that fails wins.

    in_sector, reach, fresh: (C,) bool, the candidate's sector is eligible / the cell can reach it / it is
    not near a view already taken.
    """
    out = []
    for s, r, f in zip(in_sector, reach, fresh, strict=True):
        out.append(
            "" if s and r and f else "sector locked" if not s else "unreachable" if not r else "near a taken view"
        )
    return tuple(out)
