"""A session's timeline: the session as it was after each view, rebuilt from its journal (``Session.history``).

``GET /api/sessions/{id}/timeline`` lists every step; ``/timeline/{view}`` is one, ``/timeline/{view}/candidates``
its plan's candidates (the shape of ``/candidates``). A tab's viewer shows a step with
``PUT /api/scene/{viewer}/timeline`` (app/api/scene.py). The first look replays the journal in the session's
worker; later ones are cached until the journal grows. Nothing of the session changes.
"""

from __future__ import annotations

from typing import Any

from fastapi import APIRouter

from app.api.deps import SessionDep
from app.schemas import CandidateOut, TimelineOut, TimelineStepOut
from app.serialize import candidate_json

router = APIRouter(prefix="/sessions/{session_id}/timeline", tags=["timeline"])


@router.get("", response_model=TimelineOut)
def timeline(session: SessionDep) -> dict[str, Any]:
    """Every view's step: its plan id, best view, the decision taken, voxel counts, points, coverage."""
    steps = session.history.steps()
    return {"views": len(steps), "steps": [step.summary() for step in steps]}


@router.get("/{view}", response_model=TimelineStepOut)
def timeline_step(session: SessionDep, view: int) -> dict[str, Any]:
    """The session after view ``view`` (1-based); 404 for a view it has not taken."""
    return session.history.step(view).summary()


@router.get("/{view}/candidates", response_model=list[CandidateOut])
def timeline_candidates(session: SessionDep, view: int) -> list[dict[str, Any]]:
    """The candidates of the plan made from view ``view``, scored as they were (empty when no plan was made)."""
    plan = session.history.step(view).plan
    return [] if plan is None else [candidate_json(plan, i) for i in range(len(plan.candidates))]


routers = [router]
