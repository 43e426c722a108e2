"""Algorithm 1 headless: move, capture, integrate, plan, repeat; with metrics per iteration.

Used by ``nbv scan`` and ``nbv profile``. The workbench runs the same steps one
at a time under a person's approval.
"""

from __future__ import annotations

import time
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any

import numpy as np
from numpy.typing import NDArray

from planner import Planner, PlanResult, Pose
from planner.planner import IntegrationReport
from workbench.metrics import coverage
from workbench.summaries import voxel_counts

STAGES = ("preprocess", "register", "integrate", "cluster", "ellipsoids", "candidates", "score", "select")
PLAN_STAGES = ("integrate", "cluster", "ellipsoids", "candidates", "score", "select")
"""Issue 3's plan time, frame in -> next view out. Preprocessing and ICP are timed but not counted:
they are the same work for every planner and for the paper's comparison."""


@dataclass
class IterationRecord:
    """One loop of Algorithm 1: the view captured and the plan made from it."""

    index: int
    pose: Pose
    coverage: float | None
    points: int
    plan_seconds: float
    timings: dict[str, float]
    n_occupied: int
    n_frontier: int
    t_occupied: int
    t_frontier: int
    registration: dict[str, Any] | None = None
    next_view: int | None = None
    bic: dict[str, list[tuple[int, float]]] = field(default_factory=dict)

    def to_json(self) -> dict[str, Any]:
        return {
            "index": self.index,
            "pose": self.pose.to_dict(),
            "coverage": self.coverage,
            "points": self.points,
            "plan_seconds": self.plan_seconds,
            "timings": self.timings,
            "n_occupied": self.n_occupied,
            "n_frontier": self.n_frontier,
            "t_occupied": self.t_occupied,
            "t_frontier": self.t_frontier,
            "registration": self.registration,
            "next_view": self.next_view,
            "bic": {k: [[t, b] for t, b in v] for k, v in self.bic.items()},
        }


def make_record(
    report: IntegrationReport,
    plan: PlanResult | None,
    voxels: dict[str, int],
    cov: float | None,
) -> IterationRecord:
    """Summarise one integrate + plan (None: no plan was made after it) into the metrics of metrics.json.

    voxels: the map's class counts after the integrate (:func:`workbench.summaries.voxel_counts`).
    """
    timings = {stage: 0.0 for stage in STAGES}
    for source in (report.timings, {} if plan is None else plan.timings):
        for key, value in source.items():
            timings[key] = timings.get(key, 0.0) + value
    fits = {} if plan is None else {fit.kind: fit for fit in plan.fits}
    reg = report.registration
    return IterationRecord(
        index=report.iteration,
        pose=report.T_world_camera,
        coverage=cov,
        points=report.n_points_total,
        plan_seconds=float(sum(timings[stage] for stage in PLAN_STAGES)),
        timings=timings,
        n_occupied=voxels["occupied"],
        n_frontier=voxels["frontier"],
        t_occupied=fits["occupied"].t_chosen if "occupied" in fits else 0,
        t_frontier=fits["frontier"].t_chosen if "frontier" in fits else 0,
        registration=None if reg is None else reg.summary(),
        next_view=None if plan is None else plan.best_index,
        bic={kind: list(fit.bic) for kind, fit in fits.items()},
    )


@dataclass
class ScanResult:
    records: list[IterationRecord]
    plans: list[PlanResult]
    terminated: str | None
    seconds: float


def run_scan(
    planner: Planner,
    cell: Any,
    surface_samples: NDArray[np.float64] | None = None,
    on_iteration: Callable[[IterationRecord, PlanResult], None] | None = None,
    keep_plans: bool = False,
    first_pose: Pose | None = None,
) -> ScanResult:
    """Run Algorithm 1 until the planner's termination rule or no eligible view is left.

    A plan is made after every frame (also the last), so every iteration has
    a plan time. ``surface_samples`` (M, 3) enables coverage per iteration.
    """
    t_start = time.perf_counter()
    pose = first_pose if first_pose is not None else cell.initial_pose()
    records: list[IterationRecord] = []
    plans: list[PlanResult] = []
    terminated: str | None = None
    while True:
        cell.move_to(pose)
        frame = cell.capture()
        report = planner.integrate(frame)
        plan = planner.plan(reachable=cell.is_reachable)
        cov = coverage(surface_samples, planner.cloud) if surface_samples is not None else None
        record = make_record(report, plan, voxel_counts(planner), cov)
        records.append(record)
        if keep_plans:
            plans.append(plan)
        if on_iteration is not None:
            on_iteration(record, plan)
        terminated = planner.terminated
        if terminated is not None:
            break
        if plan.best is None:
            terminated = "no_eligible_view"
            break
        pose = plan.best.T_world_camera
    return ScanResult(records, plans, terminated, time.perf_counter() - t_start)
