"""The arm of a session as the 3D views show it: where it is, the move to the selected view, and a preview of
that move on the translucent ghost in every tab showing the session."""

from __future__ import annotations

import math
from typing import Annotated, Any

from fastapi import APIRouter, Query, Request

from app.api.deps import Scene, SessionDep
from app.scene.movetarget import SessionMoves
from app.scene.pathlayer import capture_rate, no_path_json, path_preview
from app.schemas import ArmOut, ArmPreviewOut, PathOut
from workbench import Conflict

router = APIRouter(prefix="/sessions/{session_id}/arm", tags=["arm"])
path_router = APIRouter(prefix="/sessions/{session_id}/plan", tags=["arm"])


def _arm_json(scene: Any, session: Any) -> dict[str, Any]:
    arm = scene.arm_of(session)
    if arm is None:
        return {"has_arm": False, "joints": None, "plate_angle": float(session.cell.angle), "target": None,
                "unreachable": {}}  # fmt: skip
    data = session.scene_data()
    target = arm.target(data)
    reasons = {} if data.plan is None or data.plan_id is None else arm.unreachable_reasons(data.plan)
    return {
        "has_arm": True,
        "joints": [float(v) for v in session.cell.arm.joint_positions()],
        "plate_angle": float(session.cell.angle),
        "target": None if target is None else target.to_json(),
        "unreachable": {str(k): v for k, v in sorted(reasons.items())},
    }


@router.get("", response_model=ArmOut)
def arm_state(session: SessionDep, scene: Scene) -> dict[str, Any]:
    """The arm's joints and plate angle; the move to the selected target (the planner's choice, a clicked
    candidate or the custom pose: joints, plate angle, duration, or why it is unreachable); and the cell's
    reason (``no_ik``, ``joint_limit``, ``collision:<link>:<obstacle>``) for each candidate the plan found
    unreachable, by index. Without an arm model: ``has_arm`` false."""
    return _arm_json(scene, session)


@router.post("/preview", response_model=ArmPreviewOut)
def preview(session: SessionDep, scene: Scene, speed: Annotated[float, Query(gt=0.0, le=10.0)] = 1.0) -> dict[str, Any]:
    """Play the move to the selected target on the ghost arm in every tab showing this session (nothing moves).
    409 without an arm or a pending plan, 422 when the target is unreachable."""
    target, tabs = scene.preview(session, speed if math.isfinite(speed) else 1.0)
    return {"target": target.to_json(), "tabs": tabs, "seconds": target.to_json()["duration"] / speed}


@path_router.get("/path", response_model=PathOut)
def move_path(session: SessionDep, request: Request) -> dict[str, Any]:
    """The camera along the move to the selected view of the pending plan (the planner's choice, a clicked
    candidate or the custom pose), as the cell would execute it: the frames at the cell's capture rate (or the
    preview's 2.5 Hz when it does not capture during moves), where it starts and where it ends; what the 3D view's
    ``path`` layer draws. Nothing moves. 409 without a pending plan or while the session is busy; an unreachable
    view answers ``target.reachable`` false and no frames."""
    scene = request.app.state.scene
    moves = scene.moves_of(session) if scene is not None else SessionMoves(session)
    target = moves.target()
    if target is None:
        raise Conflict(f"session {session.id}: no pending plan to preview a move of (plan first), or busy")
    preview = path_preview(target, capture_rate(session.cell))
    return no_path_json(target) if preview is None else preview.to_json()


routers = [router, path_router]
