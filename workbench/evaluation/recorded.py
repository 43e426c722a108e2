"""Planners on a recorded view set: each chooses among the recorded views, an ``oracle`` gives the best order.

Every run integrates the views it takes through the whole pipeline (preprocessing, ICP, voxel map) and is scored
after each view against the set's ground truth: its reference mesh, or without one the union of all its views
registered by their recorded poses (:func:`recorded_truth`). The recorded ceiling is the coverage of all the views
together through the same pipeline (in recorded order): no order can see more, so "views to 95 %" is counted
against it.

The ``oracle`` knows the truth: it orders the views greedily by the ground-truth coverage they add (each view's
set of truth samples within 5 mm of its registered points, computed once). Greedy rather than exhaustive over
orders (10! = 3.6 million pipeline runs for ten views): the greedy order is within 1 - 1/e of the best coverage at
every step (coverage is submodular), and :func:`fewest_views` checks the one figure that matters most by brute force
over subsets: the fewest views that reach 95 % of the ceiling.
"""

from __future__ import annotations

import itertools
import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field, replace
from typing import Any

import numpy as np
from numpy.typing import NDArray
from scipy.spatial import KDTree

from devices.recorded import RecordedCell, RecordedSet, planner_config_for_set
from planner import Planner, Pose
from planner.config import PlannerConfig
from workbench.evaluation.accuracy import GroundTruth, accuracy
from workbench.evaluation.curves import area_under_curve, views_to_reach
from workbench.evaluation.scan import run_scan

ORACLE = "oracle"
"""The planner name of the ground-truth order."""
TRUTH_SAMPLES = 20000
"""Points sampled on the reference mesh (or drawn from the union of the views) to score against."""
COVER_RADIUS = 0.005
"""Metres: a truth sample is covered by a point within this distance (the project's coverage)."""
SUBSET_LIMIT = 5000
""":func:`fewest_views` tries at most this many subsets per size (all of them for a set of up to ~16 views)."""


class PointTruth(GroundTruth):
    """Ground truth given by points only (a recorded set without a reference mesh: the union of its registered
    views): distances to the surface are distances to the nearest of ``surface`` (N, 3); ``samples`` (M, 3)."""

    def __init__(self, surface: NDArray[np.float64], samples: NDArray[np.float64]) -> None:
        self.samples = np.asarray(samples, dtype=np.float64)
        if len(self.samples) == 0 or len(surface) == 0:
            raise ValueError("point truth: need points and samples")
        self.surface_points = None
        self.query_order = np.arange(len(self.samples))
        self._tree = KDTree(np.asarray(surface, dtype=np.float64))

    def distance(self, points: Any) -> NDArray[np.float64]:
        p = np.asarray(points, dtype=np.float64)
        return np.zeros(0) if len(p) == 0 else self._tree.query(p, k=1)[0]


def recorded_truth(recorded: RecordedSet, seed: int = 0) -> GroundTruth:
    """The set's truth: its reference mesh with :data:`TRUTH_SAMPLES` uniform samples, or the union of its views
    registered by their recorded poses (samples drawn from it)."""
    rng = np.random.default_rng(seed)
    if recorded.reference is not None:
        from devices.mesh import sample_surface

        return GroundTruth.of(recorded.reference, sample_surface(recorded.reference, TRUTH_SAMPLES, seed=seed))
    union = recorded.union_world()
    pick = rng.choice(len(union), size=min(TRUTH_SAMPLES, len(union)), replace=False)
    return PointTruth(union, union[pick])


def view_cover(recorded: RecordedSet, truth: GroundTruth) -> NDArray[np.bool_]:
    """(V, M) bool: which truth samples each view's registered points cover (within :data:`COVER_RADIUS`)."""
    out = np.zeros((len(recorded.views), len(truth.samples)), dtype=bool)
    for i in range(len(recorded.views)):
        points = recorded.frame(i).points_world
        if len(points):
            out[i] = KDTree(points).query(truth.samples, k=1, distance_upper_bound=COVER_RADIUS)[0] <= COVER_RADIUS
    return out


def greedy_order(cover: NDArray[np.bool_], first: int | None = None) -> list[int]:
    """The views (rows of ``cover`` (V, M)) in greedy order: each next the one adding the most covered samples
    (ties: the lower index); ``first``: the view to start from (the planners' first view, so that the orders
    compared differ in their choices only)."""
    seen = np.zeros(cover.shape[1], dtype=bool)
    left = list(range(len(cover)))
    order = []
    if first is not None:
        order.append(left.pop(first))
        seen |= cover[first]
    while left:
        gains = [int(np.count_nonzero(cover[i] & ~seen)) for i in left]
        best = left[int(np.argmax(gains))]
        order.append(best)
        left.remove(best)
        seen |= cover[best]
    return order


def fewest_views(cover: NDArray[np.bool_], fraction: float = 0.95) -> tuple[int, tuple[int, ...]] | None:
    """(k, views) the smallest subset of views whose union covers ``fraction`` of what all views cover, by brute
    force over subsets of each size (at most :data:`SUBSET_LIMIT` per size; None when none was found)."""
    target = fraction * np.count_nonzero(cover.any(axis=0))
    for k in range(1, len(cover) + 1):
        for n, subset in enumerate(itertools.combinations(range(len(cover)), k)):
            if n >= SUBSET_LIMIT:
                break
            if np.count_nonzero(cover[list(subset)].any(axis=0)) >= target - 1e-9:
                return k, subset
    return None


@dataclass
class RecordedRun:
    """One planner's run on a recorded set: the views in the order taken and the scores after each."""

    planner: str
    seed: int
    order: list[str]
    coverage: list[float]
    precision: list[float]
    fscore: list[float]
    surface_fscore: float | None = None
    cloud: NDArray[np.float64] = field(default_factory=lambda: np.zeros((0, 3)))
    poses: list[Pose] = field(default_factory=list)
    """The registered pose of each view taken (after ICP)."""
    rejected: int = 0
    """Views whose ICP correction the acceptance gate refused (their given pose was kept)."""

    def metrics(self, ceiling: float, views: int) -> dict[str, Any]:
        """Views to 95 % of ``ceiling``, AUC of coverage / ceiling over ``views`` views, the final scores."""
        curve = [min(c / ceiling, 1.0) for c in self.coverage[:views]]
        curve += [curve[-1]] * (views - len(curve))
        return {
            "planner": self.planner,
            "seed": self.seed,
            "views_to_95": views_to_reach(curve, 0.95),
            "auc": area_under_curve(curve),
            "final_coverage": self.coverage[-1],
            "final_precision_5mm": self.precision[-1],
            "final_fscore_5mm": self.fscore[-1],
            "surface_fscore_5mm": self.surface_fscore,
            "order": self.order,
        }


def recorded_config(config: PlannerConfig, views: int, seed: int) -> PlannerConfig:
    """``config`` set to take every recorded view (no early stop) and seeded with ``seed``."""
    return replace(
        config,
        termination=replace(config.termination, max_views=views, growth_threshold=0.0, stop_without_frontier=False),
        cluster=replace(config.cluster, seed=seed),
    )


def run_recorded(
    recorded: RecordedSet,
    planner_name: str,
    config: PlannerConfig,
    truth: GroundTruth,
    *,
    seed: int = 0,
    order: Sequence[int] | None = None,
    surface: bool = True,
    perturb: Callable[[int, Pose], Pose] | None = None,
) -> RecordedRun:
    """Run ``planner_name`` choosing among ``recorded``'s views (or take the views in ``order``: the oracle's, the
    recorded order), scoring after each view against ``truth``. ``perturb(index, pose)``: the pose a view is given
    to the pipeline with (e.g. an arm's error; default the recorded pose). ``surface``: also reconstruct the
    surface (TSDF) of all the views taken and score it."""
    from workbench.surface import SurfaceIntegrator, surface_accuracy

    views = len(recorded.views)
    cfg = planner_config_for_set(recorded_config(config, views, seed), recorded)
    integrator = SurfaceIntegrator() if surface else None
    coverage: list[float] = []
    precision: list[float] = []
    fscore: list[float] = []
    names: list[str] = []
    rejected = 0
    if order is None and perturb is None:
        planner = Planner(cfg, evaluator=planner_name)
        cell = RecordedCell(recorded)
        result = run_scan(
            planner,
            cell,
            truth=truth,
            on_frame=None if integrator is None else integrator.integrate,
        )
        for record in result.records:
            acc = record.accuracy or {}
            coverage.append(float(acc.get("recall_5mm") or 0.0))
            precision.append(float(acc.get("precision_5mm") or 0.0))
            fscore.append(float(acc.get("fscore_5mm") or 0.0))
            rejected += bool(record.registration is not None and not record.registration.get("accepted", True))
        names = [recorded.views[_nearest(recorded, r.pose)].name for r in result.records]
    else:
        planner = Planner(cfg, evaluator="projection")
        for index in order if order is not None else range(views):
            pose = recorded.views[index].T_world_sensor
            frame = recorded.frame(index, pose if perturb is None else perturb(index, pose))
            report = planner.integrate(frame)
            rejected += report.registration is not None and not report.registration.accepted
            if integrator is not None:
                integrator.integrate(frame.with_pose(report.T_world_camera))
            scores = accuracy(truth, planner.cloud)
            coverage.append(scores.recall_5mm)
            precision.append(scores.precision_5mm)
            fscore.append(scores.fscore_5mm)
            names.append(recorded.views[index].name)
    surface_f = None
    if integrator is not None:
        try:
            surface_f = surface_accuracy(integrator.mesh(), truth).fscore_5mm
        except ValueError:
            surface_f = math.nan
    return RecordedRun(
        planner_name, seed, names, coverage, precision, fscore, surface_f, planner.cloud, planner.views, rejected
    )


def _nearest(recorded: RecordedSet, pose: Pose) -> int:
    positions = np.array([v.T_world_sensor.translation for v in recorded.views])
    return int(np.argmin(np.linalg.norm(positions - pose.translation, axis=1)))


@dataclass
class RecordedBench:
    """The planners compared on one recorded set: per-run rows (:meth:`RecordedRun.metrics` plus the per-view
    curves), the recorded ceiling and the brute-force fewest views to 95 %."""

    name: str
    views: int
    ceiling: float
    ceiling_fscore: float
    ceiling_surface_fscore: float | None
    fewest: tuple[int, tuple[int, ...]] | None
    rows: list[dict[str, Any]]

    def summary(self) -> list[dict[str, Any]]:
        """One row per planner: the metrics, random's (or any seeded planner's) as the mean over its seeds (with
        ``views_to_95_sd`` and ``auc_sd``)."""
        out: list[dict[str, Any]] = []
        for planner in dict.fromkeys(r["planner"] for r in self.rows):
            rows = [r for r in self.rows if r["planner"] == planner]
            if len(rows) == 1:
                out.append(rows[0])
                continue
            merged: dict[str, Any] = {"planner": f"{planner} (mean of {len(rows)})", "seed": None, "order": []}
            for key in ("views_to_95", "auc", "final_coverage", "final_precision_5mm", "final_fscore_5mm"):
                values = [float(r[key]) for r in rows]
                merged[key] = float(np.mean(values))
                merged[f"{key}_sd"] = float(np.std(values, ddof=1))
            surfaces = [r["surface_fscore_5mm"] for r in rows if r["surface_fscore_5mm"] is not None]
            merged["surface_fscore_5mm"] = float(np.mean(surfaces)) if surfaces else None
            out.append(merged)
        return out

    def table(self) -> str:
        """The summary as a markdown table."""
        lines = [
            "| planner | views to 95 % | AUC | final coverage | cloud F@5mm | surface F@5mm | order |",
            "|---|---|---|---|---|---|---|",
        ]
        for r in self.summary():
            v95 = f"{r['views_to_95']:.2f} ± {r['views_to_95_sd']:.2f}" if "views_to_95_sd" in r else r["views_to_95"]
            auc = f"{r['auc']:.3f} ± {r['auc_sd']:.3f}" if "auc_sd" in r else f"{r['auc']:.3f}"
            surface = "-" if r["surface_fscore_5mm"] is None else f"{r['surface_fscore_5mm']:.3f}"
            lines.append(
                f"| {r['planner']} | {v95} | {auc} | {r['final_coverage']:.3f} | {r['final_fscore_5mm']:.3f} | "
                f"{surface} | {' '.join(r['order'])} |"
            )
        return "\n".join(lines)


def bench_recorded(
    recorded: RecordedSet,
    planners: Sequence[str],
    config: PlannerConfig,
    *,
    seeds: int = 1,
    surface: bool = True,
    on_run: Callable[[dict[str, Any]], None] | None = None,
) -> RecordedBench:
    """Run ``planners`` (``oracle`` among them: :func:`greedy_order` from the first view) on ``recorded``; random
    with ``seeds`` seeds (0, 1, ...), the others once (seed 0). The ceiling: all views in recorded order."""
    truth = recorded_truth(recorded)
    views = len(recorded.views)
    base = run_recorded(recorded, "all views", config, truth, order=list(range(views)), surface=surface)
    ceiling = base.coverage[-1]
    cover = view_cover(recorded, truth)
    rows: list[dict[str, Any]] = []
    for name in planners:
        for seed in range(seeds if name == "random" else 1):
            if name == ORACLE:
                run = run_recorded(recorded, ORACLE, config, truth, order=greedy_order(cover, first=0), surface=surface)
            else:
                run = run_recorded(recorded, name, config, truth, seed=seed, surface=surface)
            row = {
                **run.metrics(ceiling, views),
                "coverage": run.coverage,
                "precision_5mm": run.precision,
                "fscore_5mm": run.fscore,
            }
            rows.append(row)
            if on_run is not None:
                on_run(row)
    return RecordedBench(recorded.name, views, ceiling, base.fscore[-1], base.surface_fscore, fewest_views(cover), rows)
