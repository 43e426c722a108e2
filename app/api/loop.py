"""The scan loop of one session: capture, plan, select, override, approve, step, auto, stop."""

from __future__ import annotations

from typing import Annotated, Any

from fastapi import APIRouter, Body

from app.api.deps import SessionDep
from app.schemas import (
    ApproveRequest,
    AutoRequest,
    CustomPoseOut,
    CustomPoseRequest,
    PlanOut,
    SelectRequest,
    SessionOut,
    StepRequest,
)
from workbench import plan_summary

router = APIRouter(prefix="/sessions/{session_id}", tags=["loop"])


@router.post("/capture", response_model=SessionOut)
def capture(session: SessionDep) -> dict[str, Any]:
    """Capture and integrate the first view at the cell's initial pose (state new -> ready)."""
    session.capture()
    return session.status()


@router.post("/plan", response_model=PlanOut)
def plan(session: SessionDep) -> dict[str, Any]:
    """Make a new plan; any older pending plan_id goes stale."""
    return plan_summary(session.plan())


@router.put("/selection", response_model=SessionOut)
def select(session: SessionDep, body: SelectRequest) -> dict[str, Any]:
    """Highlight a candidate of the pending plan (the page's list and a click in the 3D scene both do this)."""
    session.select(body.index)
    return session.status()


@router.put("/custom_pose", response_model=CustomPoseOut)
def custom_pose(session: SessionDep, body: CustomPoseRequest) -> dict[str, Any]:
    """Propose a custom view (as the gizmo does); the answer says whether the cell can reach it."""
    return session.set_custom(body.pose.to_pose()).to_json()


@router.post("/approve", response_model=SessionOut)
def approve(session: SessionDep, body: ApproveRequest) -> dict[str, Any]:
    """Move to the approved view, capture, integrate. 409 stale/used plan_id, 422 unreachable: nothing moves."""
    pose = body.pose.to_pose() if body.pose is not None else None
    session.approve(body.plan_id, index=body.index, pose=pose)
    return session.status()


@router.post("/step", response_model=SessionOut)
def step(session: SessionDep, body: Annotated[StepRequest | None, Body()] = None) -> dict[str, Any]:
    """Plan and approve the planner's choice, ``count`` times (for scripts)."""
    session.auto.step((body or StepRequest()).count)
    return session.status()


@router.post("/auto", status_code=202, response_model=SessionOut)
def auto(session: SessionDep, body: Annotated[AutoRequest | None, Body()] = None) -> dict[str, Any]:
    """Start auto mode: up to ``count`` steps in the background; POST .../stop ends it."""
    session.auto.start((body or AutoRequest()).count)
    return session.status()


@router.post("/stop", response_model=SessionOut)
def stop(session: SessionDep) -> dict[str, Any]:
    """Stop what runs: a plan (killed at once in its worker; the session goes back to its state before it, the
    plan request answers 409), auto mode (after the current action; a plan of it is killed at once); on
    hardware also a running move of the arm and the turntable, at once (the session then goes to its error
    state, the arm's last joints in its error)."""
    session.stop()
    return session.status()


routers = [router]
