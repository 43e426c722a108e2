"""The value types of a session: decisions, plans waiting for a decision, the step a fault interrupted, the events
listeners receive, and what the 3D scene draws (the states and their table: workbench/session/states.py)."""

from __future__ import annotations

from dataclasses import dataclass
from enum import StrEnum
from typing import Any

import numpy as np
import trimesh
from numpy.typing import NDArray

from planner import PlanResult, Pose
from workbench.surface.mesh import SurfaceMesh


class SessionEvent(StrEnum):
    """What a listener (the 3D scene, the page's event stream) is told after a change."""

    STATE = "state"
    """The state or the error changed."""
    PLANNED = "planned"
    """A new pending plan."""
    CAPTURED = "captured"
    """A view was integrated (the map, the cloud and the views changed)."""
    SELECTION = "selection"
    """Another candidate is selected."""
    CUSTOM_POSE = "custom_pose"
    """A custom pose was proposed."""
    PROGRESS = "progress"
    """A long operation moved on (``status()["progress"]``, None when it ended); nothing to redraw."""


class DecisionKind(StrEnum):
    """Why the cell moved: the first view, a person's approval of the planner's choice or of another
    view (override), or the planner's choice taken without a person (step, auto)."""

    INITIAL = "initial"
    APPROVE = "approve"
    OVERRIDE = "override"
    STEP = "step"
    AUTO = "auto"


@dataclass(frozen=True)
class Decision:
    """One decision to take a view at ``pose``: which plan and candidate it answered (None for the first view
    and for a custom pose's index), the planner's best index of that plan, and whether the pose was custom."""

    kind: DecisionKind
    pose: Pose
    plan_id: str | None = None
    index: int | None = None
    best_index: int | None = None
    custom: bool = False

    def to_json(self) -> dict[str, Any]:
        """``{"kind", "plan_id", "index", "best_index", "pose", "custom"}`` (the journal's decision fields)."""
        return {
            "kind": str(self.kind),
            "plan_id": self.plan_id,
            "index": self.index,
            "best_index": self.best_index,
            "pose": self.pose.to_dict(),
            "custom": self.custom,
        }


@dataclass(frozen=True)
class CustomPose:
    """A pose a person set with the gizmo (or over REST) and whether the cell can reach it."""

    pose: Pose
    reachable: bool
    reason: str

    def to_json(self) -> dict[str, Any]:
        return {"pose": self.pose.to_dict(), "reachable": self.reachable, "reason": self.reason}


@dataclass(frozen=True, eq=False)
class PendingPlan:
    """A plan waiting for a decision. ``plan_id`` is what an approval must quote."""

    plan_id: str
    plan: PlanResult
    created: float


@dataclass(frozen=True, eq=False)
class FailedStep:
    """The step a fault interrupted, which ``retry`` re-does: move to ``decision.pose``, capture, integrate.

    entry: the plan whose decision this was (restored as pending by the fault), None for the first capture.
    """

    decision: Decision
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
    surface: SurfaceMesh | None = None
    """The reconstructed surface simplified for the page (``SurfaceUpdate.layer``), None before there is one."""
