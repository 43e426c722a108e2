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

from devices.cell import Motion, ScanCell
from devices.move_capture import MoveFrame, OnFrame
from planner import DepthFrame, Planner, PlanResult, Pose
from planner.planner import IntegrationReport
from workbench.evaluation.accuracy import ACCURACY_COLUMNS, GroundTruth, coverage_and_accuracy
from workbench.evaluation.coverage import coverage
from workbench.move_frames import KeepRule, KeptFrame, MoveIntegration, integrate_move_frames
from workbench.planning import plan_in
from workbench.session.summaries import voxel_counts

STAGES = ("preprocess", "register", "integrate", "cluster", "ellipsoids", "candidates", "score", "select")
PLAN_STAGES = ("integrate", "cluster", "ellipsoids", "candidates", "score", "select")
"""The plan time the paper's Table I compares, frame in -> next view out. Preprocessing and ICP are timed but not counted:
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
    move: dict[str, Any] | None = None
    """How the cell reached this view (``Motion.to_json``): plate angle, joints, T_base_camera, path length,
    move duration (None when the cell reports no motion)."""
    capture_seconds: float = 0.0
    """Wall time of the capture of this view."""
    plan_cpu_seconds: float = 0.0
    """CPU seconds of this process during the plan made after this view (``time.process_time``, every thread):
    its computing, which a loaded machine inflates less than the wall time ``plan_seconds``."""
    refused_moves: list[dict[str, Any]] = field(default_factory=list)
    """Views the cell refused before it reached this one (``candidate`` index, ``reason``, ``message``)."""
    accuracy: dict[str, Any] | None = None
    """The cloud's precision / recall / F at 2 and 5 mm, distances and chamfer after this view
    (``workbench.evaluation.Accuracy.to_json``; None without a ground truth)."""
    move_capture: dict[str, Any] | None = None
    """Capture during the move to this view (``MoveIntegration.to_json``: frames taken, kept, left out, integration
    and wait seconds against the move's duration); None when off."""
    move_frames: list[dict[str, Any]] = field(default_factory=list)
    """The move frames integrated on the way to this view, in stamp order: ``t`` (seconds since the move
    started), ``coverage`` after it (None without ground truth), ``points`` (the cloud's size after it)."""

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
            "move": self.move,
            "capture_seconds": self.capture_seconds,
            "plan_cpu_seconds": self.plan_cpu_seconds,
            "refused_moves": self.refused_moves,
            "accuracy": self.accuracy,
            "move_capture": self.move_capture,
            "move_frames": self.move_frames,
        }

    @property
    def move_seconds(self) -> float:
        """The move's duration (plate turn, retract, trajectory), 0 without one: robot motion only."""
        return float((self.move or {}).get("move_duration") or 0.0)

    @property
    def motion_planning_seconds(self) -> float:
        """Wall time the cell spent planning this view's move (IK, path), 0 without a move."""
        return float((self.move or {}).get("motion_planning_seconds") or 0.0)

    @property
    def robot_seconds(self) -> float:
        """Robot time of this iteration: the move's duration, the capture, the plan and the motion planning."""
        move = self.move or {}
        return (
            float(move.get("move_duration") or 0.0)
            + self.capture_seconds
            + self.plan_seconds
            + float(move.get("motion_planning_seconds") or 0.0)
        )


def make_record(
    report: IntegrationReport,
    plan: PlanResult | None,
    voxels: dict[str, int],
    cov: float | None,
) -> IterationRecord:
    """Summarise one integrate + plan (None: no plan was made after it) into the metrics of metrics.json.

    voxels: the map's class counts after the integrate (:func:`workbench.session.summaries.voxel_counts`).
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
    refused_moves: list[dict[str, Any]] = field(default_factory=list)
    """Every move the cell refused, with ``after_view`` (the views taken when it was asked) and the reason."""

    @property
    def robot_seconds(self) -> float:
        """Total robot time of the scan: moves + captures + planning (the planner's and the motion planner's)."""
        return float(sum(r.robot_seconds for r in self.records))


def _move(
    cell: ScanCell,
    pose: Pose,
    plan: PlanResult | None,
    skip: set[int],
    capture_hz: float = 0.0,
    on_frame: OnFrame | None = None,
) -> tuple[int | None, Pose | None, Motion | None, list[dict[str, Any]]]:
    """Move to ``pose`` (``plan``'s best view, or the first view without a plan); while the cell refuses
    (UnreachableError: e.g. no collision-free path), try the next best eligible candidate of ``plan``, every one
    in turn, leaving out the candidates in ``skip`` (tried already). Returns (the candidate index reached or
    None, the pose reached or None when every eligible view was refused, the cell's Motion or None, the
    refusals: ``candidate`` index, ``reason``, ``message``). Without a plan (the first view) a refusal is raised:
    there is nothing else to try. ``capture_hz``, ``on_frame``: capture during the move (``Cell.move_to``)."""
    from devices.protocols import UnreachableError

    tries: list[tuple[int | None, Pose]] = []
    if plan is None:
        tries.append((None, pose))
    else:
        ranked = sorted((s for s in plan.scores if s.eligible and s.index not in skip), key=lambda s: -s.score)
        best = [s for s in ranked if s.index == plan.best_index]
        ranked = best + [s for s in ranked if s.index != plan.best_index]
        tries += [(s.index, plan.candidates[s.index].T_world_camera) for s in ranked]
    refused: list[dict[str, Any]] = []
    for index, target in tries:
        then = [] if plan is None else plan.then_poses(index)  # the views the tour expects next, if any
        try:
            motion = cell.move_to(target, then=then, capture_hz=capture_hz, on_frame=on_frame)
            return index, target, motion, refused
        except UnreachableError as exc:
            if plan is None:
                raise
            refused.append({"candidate": index, "reason": exc.reason, "message": str(exc)})
    return None, None, None, refused


def run_scan(
    planner: Planner,
    cell: ScanCell,
    surface_samples: NDArray[np.float64] | None = None,
    on_iteration: Callable[[IterationRecord, PlanResult], None] | None = None,
    keep_plans: bool = False,
    first_pose: Pose | None = None,
    on_frame: Callable[[DepthFrame], None] | None = None,
    truth: GroundTruth | None = None,
    on_move_frame: Callable[[DepthFrame], None] | None = None,
) -> ScanResult:
    """Run Algorithm 1 until the planner's termination rule or no eligible view is left.

    A view the cell refuses never ends the scan: the next best eligible view is taken and the refusal recorded
    (``IterationRecord.refused_moves``, ``ScanResult.refused_moves``); so is a view whose frame the planner
    cannot use (reason ``empty_frame``: no return, or nothing left on the object, e.g. beyond a short-range
    sensor's reach). Only "every eligible view refused / none left" ends it (``no_eligible_view``); an unusable
    first frame is raised (there is no plan to go on from).

    A plan is made after every frame (also the last), so every iteration has
    a plan time. ``surface_samples`` (M, 3) enables coverage per iteration, ``truth`` the accuracy
    (precision, recall, F, chamfer: ``IterationRecord.accuracy``). ``on_frame`` hears each integrated frame
    with its registered pose (e.g. a surface integrator), before the plan.

    Capture during moves (``cell.config.move_capture_hz`` > 0): the frames the cell takes on the way to a view are
    integrated before the view (in stamp order, :func:`workbench.move_frames.integrate_move_frames` under the cell's
    keep rule; ``on_move_frame`` hears each kept one with its registered pose), each kept frame's coverage recorded at its stamp
    (``IterationRecord.move_frames``). A move whose view turns out unusable keeps its frames in the map (they were
    seen): they are recorded with the next view taken.
    """
    t_start = time.perf_counter()
    pose = first_pose if first_pose is not None else cell.initial_pose()
    records: list[IterationRecord] = []
    plans: list[PlanResult] = []
    terminated: str | None = None
    plan: PlanResult | None = None
    refusals: list[dict[str, Any]] = []
    tried: set[int] = set()  # candidates of the current plan refused or unusable
    pending: list[dict[str, Any]] = []  # the refusals since the last view taken
    hz = float(cell.config.move_capture_hz)
    rule = KeepRule.of(cell.config)
    moved: list[dict[str, Any]] = []  # the move frames kept since the last view taken
    move_blocks: list[MoveIntegration] = []
    last_slowest = 0.0  # the slowest move frame of the last move: the next move's first estimate

    def kept(frame: KeptFrame) -> None:
        if on_move_frame is not None:
            on_move_frame(frame.frame.with_pose(frame.T_world_camera))
        cov = None if surface_samples is None else coverage(surface_samples, planner.cloud)
        moved.append({"t": frame.t, "coverage": cov, "points": len(planner.cloud)})

    while True:
        taken: list[MoveFrame] = []
        index, reached, motion, refused = _move(cell, pose, plan, tried, hz, taken.append)
        if taken and motion is not None:
            prior = move_blocks[-1].slowest if move_blocks else last_slowest
            move_blocks.append(integrate_move_frames(planner, taken, motion.duration, rule, kept, prior=prior))
            last_slowest = move_blocks[-1].slowest
        refusals += [{"after_view": len(records), **r} for r in refused]
        pending += refused
        tried |= {r["candidate"] for r in refused if r["candidate"] is not None}
        if reached is None:
            terminated = "no_eligible_view"  # every eligible view was refused: recorded in refused_moves
            break
        pose = reached
        t0 = time.perf_counter()
        frame = cell.capture()
        capture_seconds = time.perf_counter() - t0
        try:
            report = planner.integrate(frame)
        except ValueError as exc:  # an unusable frame (state unchanged): the next eligible view of the same plan
            if plan is None or index is None:
                raise
            empty = {"candidate": index, "reason": "empty_frame", "message": str(exc)}
            refusals.append({"after_view": len(records), **empty})
            pending.append(empty)
            tried.add(index)
            continue
        refused, pending, tried = pending, [], set()
        if on_frame is not None:
            on_frame(frame.with_pose(report.T_world_camera))
        cpu0 = time.process_time()
        plan = plan_in(cell, planner)
        plan_cpu_seconds = time.process_time() - cpu0
        cov, measured = coverage_and_accuracy(surface_samples, truth, planner.cloud)
        record = make_record(report, plan, voxel_counts(planner), cov)
        record.capture_seconds = capture_seconds
        record.plan_cpu_seconds = plan_cpu_seconds
        record.refused_moves = refused
        if measured is not None:
            record.accuracy = measured.to_json()
        record.move = None if motion is None else motion.to_json()
        if move_blocks:
            record.move_capture = _merged(move_blocks)
        record.move_frames, moved, move_blocks = moved, [], []
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
    return ScanResult(records, plans, terminated, time.perf_counter() - t_start, refusals)


def _merged(blocks: list[MoveIntegration]) -> dict[str, Any]:
    """One ``move_capture`` block of the moves since the last view (usually one; more when a view was unusable)."""
    out = blocks[-1].to_json()
    for block in blocks[:-1]:
        for key, value in block.to_json().items():
            out[key] += value
    return out


def final_accuracy(records: list[IterationRecord]) -> dict[str, Any]:
    """The last view's :data:`ACCURACY_COLUMNS` (None each without a ground truth)."""
    acc = records[-1].accuracy if records else None
    return {k: None if acc is None else acc[k] for k in ACCURACY_COLUMNS}


def icp_rejections(records: list[IterationRecord]) -> list[dict[str, Any]]:
    """The views whose ICP result was rejected, and why (``view``, ``reason``)."""
    return [
        {"view": r.index, "reason": r.registration.get("reason")}
        for r in records
        if r.registration is not None and not r.registration.get("accepted", True)
    ]
