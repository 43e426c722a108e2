"""Baseline view evaluators: ray-casting information gain (APORA, Isler et al. OA / UV / RSE) and random.

They implement ``planner.evaluators.ViewEvaluator`` on the same voxel map, the
same candidates and the same eligibility as the paper's projection evaluator, so
``Planner(config, evaluator="raycast-oa")`` swaps only the scoring.

Every candidate is scored (eligible or not, like ``projection``); the choice
among the eligible ones is ``partitions.select_best``. A ``ViewScore`` carries
``score = frontier = gain``, ``occupied = 0`` and empty per-ellipsoid arrays.
``Evaluation.timings["score"]`` is the whole candidate-evaluation stage (object
probabilities, rays, traversal, gains); ``last_breakdown`` splits it.
"""

from __future__ import annotations

import time
from collections.abc import Callable, Sequence
from typing import TYPE_CHECKING, Literal

import numpy as np
from numpy.typing import ArrayLike, NDArray

from planner.baselines import gains
from planner.baselines.rays import view_rays, walk_rays
from planner.config import PlannerConfig
from planner.evaluators import Evaluation, EvaluationContext
from planner.types import Intrinsics, Pose, ViewScore

if TYPE_CHECKING:
    from planner.voxel_map import VoxelMap

GainKind = Literal["apora", "oa", "uv", "rse"]
GAIN_KINDS: tuple[GainKind, ...] = ("apora", "oa", "uv", "rse")

VIEWS_PER_BATCH = 16
"""Candidates whose rays are generated and traversed together: large enough to amortise numpy's
per-call overhead, small enough for the working set (~2000 rays per view) to stay in cache."""

_ACCUMULATORS: dict[GainKind, type[gains.RayGainAccumulator]] = {
    "apora": gains.AporaAccumulator,
    "oa": gains.OcclusionAwareAccumulator,
    "uv": gains.UnobservedVoxelAccumulator,
    "rse": gains.RearSideEntropyAccumulator,
}


def _empty(dtype: type) -> NDArray:
    a = np.zeros(0, dtype=dtype)
    a.setflags(write=False)
    return a


_NO_RANKS, _NO_FLOATS = _empty(np.int64), _empty(np.float64)


def gain_scores(values: NDArray[np.float64], eligible: NDArray[np.bool_]) -> tuple[ViewScore, ...]:
    """One ``ViewScore`` per candidate for evaluators without ellipsoids: score = frontier = value, occupied = 0."""
    return tuple(
        ViewScore(
            index=i,
            score=float(g),
            frontier=float(g),
            occupied=0.0,
            eligible=bool(e),
            ranks=_NO_RANKS,
            weights=_NO_FLOATS,
            pixels=_NO_FLOATS,
            weighted=_NO_FLOATS,
        )
        for i, (g, e) in enumerate(zip(values, eligible, strict=True))
    )


def raycast_view_gains(
    classes: NDArray[np.uint8],
    origin: ArrayLike,
    resolution: float,
    box_lower: ArrayLike,
    box_upper: ArrayLike,
    poses: Sequence[Pose],
    intrinsics: Intrinsics,
    kind: GainKind,
    stride_voxels: float = 1.0,
    breakdown: dict[str, float] | None = None,
    progress: Callable[[int, int], None] | None = None,
) -> NDArray[np.float64]:
    """(C,) float64 gain of each view in ``poses``: the sum of its ray gains (``gains`` module).

    classes: (X, Y, Z) uint8 voxel classes; origin: (3,) world position of voxel (0, 0, 0)'s
    lower corner; box_lower/box_upper: (3,) the bounding box B (clipped to the grid).
    Rays: ``rays.view_rays``; each is traversed until it leaves B or after its first
    OCCUPIED voxel. ``breakdown``, if given, receives seconds per part ("object_probability",
    "rays", "traverse" including the gains), the number of rays and of voxel visits. ``progress``, if given,
    gets ``(views done, views)`` after each batch of views.
    """
    if kind not in _ACCUMULATORS:
        raise ValueError(f"kind: one of {', '.join(GAIN_KINDS)}, got {kind!r}")
    c = np.asarray(classes)
    if c.ndim != 3 or c.dtype != np.uint8:
        raise ValueError(f"classes: expected a 3-D uint8 array, got {c.ndim}-D {c.dtype}")
    o = np.asarray(origin, dtype=np.float64)
    lo = np.maximum(np.asarray(box_lower, dtype=np.float64), o)
    hi = np.minimum(np.asarray(box_upper, dtype=np.float64), o + np.array(c.shape) * resolution)
    parts = {"object_probability": 0.0, "rays": 0.0, "traverse": 0.0, "n_rays": 0.0, "n_visits": 0.0}
    total = np.zeros(len(poses))
    if c.size == 0 or np.any(hi <= lo) or len(poses) == 0:
        if breakdown is not None:
            breakdown.update(parts)
        return total

    t0 = time.perf_counter()
    classes_flat = c.reshape(-1)
    pobj_flat = gains.object_probability_grid(c, o, resolution).reshape(-1) if kind == "apora" else None
    parts["object_probability"] = time.perf_counter() - t0
    shape = (int(c.shape[0]), int(c.shape[1]), int(c.shape[2]))
    occupied = gains.OCCUPIED_LUT
    for start in range(0, len(poses), VIEWS_PER_BATCH):
        t0 = time.perf_counter()
        rays = view_rays(poses[start : start + VIEWS_PER_BATCH], intrinsics, lo, hi, resolution, stride_voxels)
        t1 = time.perf_counter()
        acc = _ACCUMULATORS[kind](len(rays))
        visits = [0]

        def visit(rows: NDArray[np.int64], lin: NDArray[np.int64], acc=acc, visits=visits) -> NDArray[np.bool_]:
            visits[0] += len(rows)
            cls = classes_flat[lin]
            acc.add(rows, cls, None if pobj_flat is None else pobj_flat[lin])
            return occupied[cls]  # the ray ends on the first occupied voxel

        walk_rays(rays.origins, rays.directions, rays.t_enter, rays.t_exit, o, resolution, shape, visit)
        total[start : start + len(rays.counts)] += np.bincount(rays.owner, weights=acc.gain, minlength=len(rays.counts))
        parts["rays"] += t1 - t0
        parts["traverse"] += time.perf_counter() - t1
        parts["n_rays"] += len(rays)
        parts["n_visits"] += visits[0]
        if progress is not None:
            progress(min(start + VIEWS_PER_BATCH, len(poses)), len(poses))
    if breakdown is not None:
        breakdown.update(parts)
    return total


class RaycastEvaluator:
    """Scores each candidate by the ray-casting information gain ``kind`` (see ``gains``)."""

    name: str = "raycast"
    kind: GainKind = "oa"
    stages = ("ray casting",)

    def __init__(self, config: PlannerConfig, stride_voxels: float = 1.0) -> None:
        self.config = config
        self.stride_voxels = stride_voxels
        self.last_breakdown: dict[str, float] = {}

    def reset(self) -> None:
        """Stateless: nothing to forget between scans."""

    def evaluate(self, ctx: EvaluationContext) -> Evaluation:
        t0 = time.perf_counter()
        ctx.progress("ray casting", 0, len(ctx.candidates))
        vm: VoxelMap = ctx.voxel_map
        classes = np.asarray(vm.classes)
        origin = np.asarray(vm.origin, dtype=np.float64)
        res = float(vm.resolution)
        bbox = vm.bbox
        lower = origin if bbox is None else bbox.lower
        upper = origin + np.array(classes.shape) * res if bbox is None else bbox.upper
        breakdown: dict[str, float] = {}
        values = raycast_view_gains(
            classes,
            origin,
            res,
            lower,
            upper,
            [c.T_world_camera for c in ctx.candidates],
            ctx.intrinsics,
            self.kind,
            self.stride_voxels,
            breakdown,
            lambda done, total: ctx.progress("ray casting", done, total),
        )
        scores = gain_scores(values, np.asarray(ctx.eligible, dtype=bool))
        self.last_breakdown = breakdown
        return Evaluation(scores, timings={"score": time.perf_counter() - t0})


class AporaEvaluator(RaycastEvaluator):
    """APORA occlusion-aware object-probability gain (Daudelin & Campbell 2017, as in Pan's simulator)."""

    name = "raycast-apora"
    kind = "apora"


class OcclusionAwareEvaluator(RaycastEvaluator):
    """Isler et al. 2016 occlusion-aware volumetric information."""

    name = "raycast-oa"
    kind = "oa"


class UnobservedVoxelEvaluator(RaycastEvaluator):
    """Isler et al. 2016 unobserved-voxel count, weighted by visibility."""

    name = "raycast-uv"
    kind = "uv"


class RearSideEntropyEvaluator(RaycastEvaluator):
    """Isler et al. 2016 rear-side entropy."""

    name = "raycast-rse"
    kind = "rse"


class RandomEvaluator:
    """A floor: a uniformly random eligible candidate (i.i.d. uniform scores from ``ctx.rng``)."""

    name = "random"
    stages = ("score",)

    def __init__(self, config: PlannerConfig) -> None:
        self.config = config

    def reset(self) -> None:
        """Stateless: the randomness comes from ``ctx.rng``."""

    def evaluate(self, ctx: EvaluationContext) -> Evaluation:
        t0 = time.perf_counter()
        values = ctx.rng.random(len(ctx.candidates))
        scores = gain_scores(values, np.asarray(ctx.eligible, dtype=bool))
        return Evaluation(scores, timings={"score": time.perf_counter() - t0})


BASELINES: dict[str, Callable[[PlannerConfig], RaycastEvaluator | RandomEvaluator]] = {
    cls.name: cls
    for cls in (AporaEvaluator, OcclusionAwareEvaluator, UnobservedVoxelEvaluator, RearSideEntropyEvaluator)
}
BASELINES[RandomEvaluator.name] = RandomEvaluator
