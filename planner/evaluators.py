"""View evaluators: how a planner turns the voxel map into a score per candidate.

The paper's evaluator (``projection``) fits ellipsoids to the occupied and
frontier voxels (§III-D) and scores each candidate by projecting them (§III-E).
Baselines (ray casting, random) plug in through the same protocol and are
registered in ``EVALUATORS`` by their own modules.
"""

from __future__ import annotations

import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Protocol

import numpy as np
from numpy.typing import NDArray

from planner.config import PlannerConfig
from planner.ellipsoids import EllipsoidFitter, enclose
from planner.frontier_age import FrontierAge, ellipsoid_weights
from planner.progress import StageFn, ignore
from planner.scoring import score_views
from planner.types import Candidate, ClusterFit, Ellipsoid, Intrinsics, ViewScore, VoxelClass
from planner.visibility import score_visible_frontier

if TYPE_CHECKING:
    from planner.voxel_map import VoxelMap


@dataclass(frozen=True, eq=False)
class EvaluationContext:
    """What an evaluator may look at.

    eligible: (C,) bool, candidates the partition rule and reachability allow.
    progress: ``(stage, done, total)`` for the evaluator's stages (its ``stages`` attribute names them).
    """

    voxel_map: VoxelMap
    candidates: tuple[Candidate, ...]
    intrinsics: Intrinsics
    eligible: NDArray[np.bool_]
    rng: np.random.Generator
    progress: StageFn = ignore


@dataclass(frozen=True, eq=False)
class Evaluation:
    """Scores in candidate order, plus what the evaluator built to get them."""

    scores: tuple[ViewScore, ...]
    ellipsoids: tuple[Ellipsoid, ...] = ()
    fits: tuple[ClusterFit, ...] = ()
    timings: dict[str, float] = field(default_factory=dict)


class ViewEvaluator(Protocol):
    """Scores every candidate of a context; higher is better.

    An evaluator may name the stages it reports through ``ctx.progress`` in a ``stages`` tuple (in order);
    without it a plan shows one stage, "evaluate".
    """

    name: str

    def evaluate(self, ctx: EvaluationContext) -> Evaluation: ...

    def reset(self) -> None: ...


class ProjectionEvaluator:
    """The paper's method: GMM + BIC clusters, MVEE ellipsoids, projected conics with rank weights."""

    name = "projection"
    stages = ("fit occupied", "fit frontier", "score")

    def __init__(self, config: PlannerConfig) -> None:
        self.config = config
        res = config.voxel.resolution
        self._fitters = {
            "occupied": EllipsoidFitter(config.cluster, res, "occupied"),
            "frontier": EllipsoidFitter(config.cluster, res, "frontier"),
        }

    def reset(self) -> None:
        for fitter in self._fitters.values():
            fitter.reset()

    def fit(self, ctx: EvaluationContext) -> tuple[list[Ellipsoid], list[ClusterFit], dict[str, float]]:
        """Ellipsoids of the occupied then the frontier voxels, their model selections, and the seconds spent.
        Both kinds are clustered first and their ellipsoids solved in one batch (:func:`planner.ellipsoids.enclose`:
        the same ellipsoids as one kind at a time)."""
        timings = {"cluster": 0.0, "ellipsoids": 0.0}
        clusters = []
        for kind, cls in (("occupied", VoxelClass.OCCUPIED), ("frontier", VoxelClass.FRONTIER)):
            stage = f"fit {kind}"
            ctx.progress(stage, 0, 1)
            clusters.append(
                self._fitters[kind].cluster(
                    ctx.voxel_map.centers(cls), lambda done, total, s=stage: ctx.progress(s, done, total)
                )
            )
        ellipsoids: list[Ellipsoid] = []
        fits: list[ClusterFit] = []
        for (found, fit), c in zip(enclose(clusters), clusters, strict=True):
            ellipsoids.extend(found)
            fits.append(fit)
            for stage in ("cluster", "ellipsoids"):
                timings[stage] += c.fitter.last_timings.get(stage, 0.0)
        return ellipsoids, fits, timings

    def evaluate(self, ctx: EvaluationContext) -> Evaluation:
        ellipsoids, fits, timings = self.fit(ctx)
        ctx.progress("score", 0, len(ctx.candidates))
        t0 = time.perf_counter()
        scores = score_views(ellipsoids, ctx.candidates, ctx.intrinsics, self.config.scoring, ctx.eligible)
        timings["score"] = time.perf_counter() - t0
        return Evaluation(tuple(scores), tuple(ellipsoids), tuple(fits), timings)


class ZBufferEvaluator(ProjectionEvaluator):
    """The paper's ellipsoids, scored by the frontier each view shows in front of every occupied ellipsoid.

    Same fit as ``projection`` (§III-D); the score is V of ``planner.visibility`` (a rasterised
    z-buffer of the ellipsoids per candidate) instead of the paper's rank-weighted F.
    """

    name = "projection-zbuffer"

    def __init__(self, config: PlannerConfig) -> None:
        super().__init__(config)
        self._age = FrontierAge()

    def reset(self) -> None:
        super().reset()
        self._age.reset()

    def frontier_weights(self, ctx: EvaluationContext, ellipsoids: Sequence[Ellipsoid]) -> NDArray[np.float64]:
        """(E,) w_e: 1, or with ``zbuffer.frontier_decay`` < 1 the mean decayed weight of each frontier ellipsoid."""
        decay = self.config.zbuffer.frontier_decay
        centers, ages = self._age.update_map(ctx.voxel_map)
        if decay == 1.0:
            return np.ones(len(ellipsoids))
        return ellipsoid_weights(ellipsoids, centers, decay ** ages.astype(np.float64))

    def evaluate(self, ctx: EvaluationContext) -> Evaluation:
        ellipsoids, fits, timings = self.fit(ctx)
        ctx.progress("score", 0, len(ctx.candidates))
        t0 = time.perf_counter()
        weights = self.frontier_weights(ctx, ellipsoids)
        scores = score_visible_frontier(
            ellipsoids,
            ctx.candidates,
            ctx.intrinsics,
            self.config.zbuffer,
            ctx.eligible,
            self.config.voxel.resolution,
            weights,
        )
        timings["score"] = time.perf_counter() - t0
        return Evaluation(tuple(scores), tuple(ellipsoids), tuple(fits), timings)


EVALUATORS: dict[str, Callable[[PlannerConfig], ViewEvaluator]] = {
    "projection": ProjectionEvaluator,
    "projection-zbuffer": ZBufferEvaluator,
}


def make_evaluator(name: str, config: PlannerConfig) -> ViewEvaluator:
    """The evaluator registered as ``name``; ValueError lists the known names."""
    _load_plugins()
    try:
        factory = EVALUATORS[name]
    except KeyError:
        raise ValueError(f"planner: unknown planner {name!r} (known: {', '.join(sorted(EVALUATORS))})") from None
    return factory(config)


def evaluator_names() -> list[str]:
    _load_plugins()
    return sorted(EVALUATORS)


def _load_plugins() -> None:
    """Import modules that register further evaluators (baselines), if present."""
    import importlib

    for module in ("planner.baselines", "planner.tour", "planner.paths"):
        try:
            importlib.import_module(module)
        except ModuleNotFoundError as exc:
            if exc.name != module:
                raise
