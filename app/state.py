"""The value types of a session's state machine: states, plans waiting for a decision, what the scene draws."""

from __future__ import annotations

from dataclasses import dataclass
from enum import StrEnum
from typing import Any

import numpy as np
import trimesh
from numpy.typing import NDArray

from planner import PlanResult, Pose


class State(StrEnum):
    NEW = "new"
    CAPTURING = "capturing"
    READY = "ready"
    PLANNING = "planning"
    PLANNED = "planned"
    MOVING = "moving"
    AUTO = "auto"
    DONE = "done"
    ERROR = "error"
    INTERRUPTED = "interrupted"
    """Journaled by an earlier server process that stopped; POST .../resume rebuilds it (never a live state)."""


BUSY = frozenset({State.CAPTURING, State.PLANNING, State.MOVING, State.AUTO})
CAN_PLAN = frozenset({State.READY, State.PLANNED, State.DONE, State.ERROR})


@dataclass(frozen=True)
class CustomPose:
    """A pose a person set with the gizmo (or over REST) and whether the cell can reach it."""

    pose: Pose
    reachable: bool
    reason: str


@dataclass(frozen=True, eq=False)
class PendingPlan:
    """A plan waiting for a decision. ``plan_id`` is what an approval must quote."""

    plan_id: str
    plan: PlanResult
    created: float


@dataclass(frozen=True, eq=False)
class FailedStep:
    """The step a fault interrupted, which ``retry`` re-does: move to ``pose``, capture, integrate.

    action: "initial" (the first capture), "approve", "override", "step" or "auto".
    entry: the plan whose decision this was (restored as pending by the fault), None for the first capture.
    """

    action: str
    pose: Pose
    decision: dict[str, Any]
    entry: PendingPlan | None


@dataclass(frozen=True, eq=False)
class SceneData:
    """What the 3D scene draws, copied out under the lock."""

    session_id: str
    plan: PlanResult | None
    plan_id: str | None
    views: tuple[Pose, ...]
    cloud: NDArray[np.float64]
    selected: int | None
    custom: CustomPose | None
    mesh: trimesh.Trimesh
    plate_radius: float
    fov_y: float
    aspect: float


def plan_summary(entry: PendingPlan) -> dict[str, Any]:
    """``{"plan_id", "best": {"index", "pose", "score"} | None, "timings", ...}``."""
    plan = entry.plan
    best = None
    if plan.best_index is not None:
        best = {
            "index": plan.best_index,
            "pose": plan.candidates[plan.best_index].T_world_camera.to_dict(),
            "score": float(plan.scores[plan.best_index].score),
        }
    return {
        "plan_id": entry.plan_id,
        "iteration": plan.iteration,
        "best": best,
        "timings": {k: float(v) for k, v in plan.timings.items()},
        "n_candidates": len(plan.candidates),
        "n_eligible": int(sum(s.eligible for s in plan.scores)),
        "terminated": plan.terminated,
    }


def custom_json(custom: CustomPose) -> dict[str, Any]:
    return {"pose": custom.pose.to_dict(), "reachable": custom.reachable, "reason": custom.reason}
