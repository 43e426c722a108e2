"""One builder per fact a session reports: a plan's journal fields and REST summary, the best view, voxel
counts, a capture's journal fields, the session status. Every caller (session, record, rebuild, registry,
the CLI) uses these, so each fact has one shape."""

from __future__ import annotations

from dataclasses import dataclass, field, fields
from typing import Any

from planner import Planner, PlanResult, VoxelClass
from planner.planner import IntegrationReport
from workbench.session.states import Listed, State
from workbench.session.values import CustomPose, PendingPlan

VOXEL_CLASSES = ("occupied", "frontier", "unknown", "empty")


def voxel_counts(planner: Planner) -> dict[str, int]:
    """``{"occupied", "frontier", "unknown", "empty"}``: how many voxels of each class the map holds."""
    vm = planner.voxel_map
    return {name: vm.count(VoxelClass[name.upper()]) for name in VOXEL_CLASSES}


def best_of(plan: PlanResult) -> dict[str, Any] | None:
    """``{"index", "score", "pose"}`` of the plan's best view, or None."""
    best = plan.best_index
    if best is None:
        return None
    return {
        "index": best,
        "score": float(plan.scores[best].score),
        "pose": plan.candidates[best].T_world_camera.to_dict(),
    }


def fit_json(fit: Any) -> dict[str, Any]:
    """A ClusterFit as ``{"kind", "t_chosen", "n_points", "seconds", "bic": [[t, bic], ...]}``."""
    return {
        "kind": fit.kind,
        "t_chosen": int(fit.t_chosen),
        "n_points": int(fit.n_points),
        "seconds": float(fit.seconds),
        "bic": [[int(t), float(b)] for t, b in fit.bic],
    }


def plan_fields(plan: PlanResult) -> dict[str, Any]:
    """The journal's ``plan`` event fields of ``plan`` (besides ``plan_id``): what the record, the status and
    the rebuild's check read."""
    return {
        "iteration": plan.iteration,
        "best": best_of(plan),
        "timings": {k: float(v) for k, v in plan.timings.items()},
        "n_candidates": len(plan.candidates),
        "n_eligible": int(sum(s.eligible for s in plan.scores)),
        "n_ellipsoids": {"occupied": len(plan.occupied_ellipsoids), "frontier": len(plan.frontier_ellipsoids)},
        "fits": [fit_json(f) for f in plan.fits],
        "terminated": plan.terminated,
    }


PLAN_SUMMARY_KEYS = ("iteration", "best", "timings", "n_candidates", "n_eligible", "terminated")


def plan_summary(entry: PendingPlan) -> dict[str, Any]:
    """``{"plan_id", "iteration", "best": {"index", "pose", "score"} | None, "timings", "n_candidates",
    "n_eligible", "terminated"}``: the REST answer of a plan, a subset of its journal fields."""
    fields = plan_fields(entry.plan)
    return {"plan_id": entry.plan_id, **{k: fields[k] for k in PLAN_SUMMARY_KEYS}}


def capture_fields(report: IntegrationReport, voxels: dict[str, int], coverage: float | None) -> dict[str, Any]:
    """The journal's ``capture`` event fields that come from integrating the frame."""
    reg = report.registration
    return {
        "iteration": report.iteration,
        "pose_used": report.T_world_camera.to_dict(),
        "points_frame": report.n_points_frame,
        "points": report.n_points_total,
        "growth": report.growth,
        "voxels": voxels,
        "coverage": coverage,
        "registration": None if reg is None else reg.summary(),
        "timings": {k: float(v) for k, v in report.timings.items()},
    }


def _doc(text: str) -> dict[str, str]:
    """A field's documentation, as its metadata (the response schema's description)."""
    return {"doc": text}


@dataclass(frozen=True)
class SessionStatus:
    """The status of a session, live or listed from the journal of an earlier server: the one shape of it (the
    web layer's response schema is built from these fields and their docs)."""

    id: str
    model: str
    source: str = field(metadata=_doc("sim, replay, hardware (a cell file's devices, or its dry run), or journal"))
    state: str = field(metadata=_doc(f"{', '.join([*State, *Listed])} (the last two: listed from a journal, not live)"))
    iteration: int = field(metadata=_doc("views integrated"))
    coverage: float | None = field(metadata=_doc("ground-truth coverage of the last view; null without a ground truth"))
    points: int = field(metadata=_doc("points in the accumulated cloud"))
    voxels: dict[str, int] = field(metadata=_doc("voxel counts by class: occupied, frontier, unknown, empty"))
    pending_plan: dict[str, Any] | None = field(metadata=_doc("the plan waiting for a decision (its summary)"))
    selected: int | None = field(metadata=_doc("the highlighted candidate of the pending plan"))
    custom_pose: dict[str, Any] | None = field(
        metadata=_doc("the custom view proposed, and whether the cell reaches it")
    )
    error: str | None = field(metadata=_doc("what went wrong last (a fault, a journal that cannot be written)"))
    retry: str | None = field(metadata=_doc("in state error: the failed step a retry re-does"))
    terminated: str | None = field(metadata=_doc("why the planner's termination rule fired"))
    auto_remaining: int = field(metadata=_doc("steps auto mode still has to go"))
    moves: int = field(metadata=_doc("moves of the cell"))
    seed: int = field(metadata=_doc("seeds the planner's fits and the simulated noise"))
    planner: str = field(default="projection", metadata=_doc("the view evaluator this session plans with"))
    guided: bool = field(
        default=False, metadata=_doc("guided mode: the page explains each step (set at create, e.g. by a class)")
    )
    progress: dict[str, Any] | None = field(default=None, metadata=_doc("the long operation running now, if any"))
    views: list[dict[str, Any]] = field(
        default_factory=list,
        metadata=_doc(
            "per view: iteration, decision, coverage, precision_5mm, fscore_5mm, precision_2mm, fscore_2mm, "
            "chamfer_mm (null without a ground truth), icp_rejected (why ICP rejected the frame, null when it "
            "accepted or did not run), refused (the planner's choices refused before this view: candidate, reason)"
        ),
    )
    refused_moves: int = field(default=0, metadata=_doc("moves refused (or frames unusable) of the planner's choices"))

    def to_json(self) -> dict[str, Any]:
        return {f.name: getattr(self, f.name) for f in fields(self)}


def session_status(
    record: Any,
    *,
    state: State | Listed,
    source: str,
    planner: str = "projection",
    pending: PendingPlan | None = None,
    selected: int | None = None,
    custom: CustomPose | None = None,
    error: str | None = None,
    retry: str | None = None,
    terminated: str | None = None,
    auto_remaining: int = 0,
    moves: int = 0,
    progress: dict[str, Any] | None = None,
) -> dict[str, Any]:
    """The :class:`SessionStatus` of a live or an interrupted session, as JSON.

    record: the session's :class:`workbench.session.record.SessionRecord` (id, model, seed and the last capture).
    progress: the running long operation (``workbench.progress.Progress.to_json``), None when none runs.
    """
    last = record.iterations[-1] if record.iterations else None
    return SessionStatus(
        id=record.session_id,
        model=record.model,
        source=source,
        state=str(state),
        iteration=len(record.iterations),
        coverage=None if last is None else last["coverage"],
        points=0 if last is None else last["points"],
        voxels=dict(record.voxels),
        pending_plan=None if pending is None else plan_summary(pending),
        selected=selected,
        custom_pose=None if custom is None else custom.to_json(),
        error=error,
        retry=retry,
        terminated=terminated,
        auto_remaining=auto_remaining,
        moves=moves,
        seed=record.seed,
        planner=planner,
        guided=bool(getattr(record, "guided", False)),
        progress=progress,
        views=[view_summary(r) for r in record.iterations],
        refused_moves=len(getattr(record, "refusals", [])),
    ).to_json()


VIEW_ACCURACY = ("precision_5mm", "fscore_5mm", "precision_2mm", "fscore_2mm", "chamfer_mm")


def view_summary(iteration: dict[str, Any]) -> dict[str, Any]:
    """One view of the status's ``views``: its coverage and accuracy, ICP's verdict, the refusals before it."""
    scores = iteration.get("accuracy") or {}
    reg = iteration.get("registration") or {}
    return {
        "iteration": iteration["iteration"],
        "decision": iteration.get("decision"),
        "coverage": iteration.get("coverage"),
        **{k: scores.get(k) for k in VIEW_ACCURACY},
        "icp_rejected": None if not reg or reg.get("accepted", True) else reg.get("reason"),
        "refused": [{"candidate": r.get("candidate"), "reason": r.get("reason")} for r in iteration.get("refused", [])],
    }
