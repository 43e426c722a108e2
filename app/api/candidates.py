"""The candidates of a session's plan: the list, one candidate's score breakdown, its projection image."""

from __future__ import annotations

from typing import Annotated, Any, Literal

from fastapi import APIRouter, Query, Response

from app.api.deps import SessionDep
from app.schemas import CandidateDetail, CandidateOut
from app.serialize import candidate_detail, candidate_json

router = APIRouter(prefix="/sessions/{session_id}/candidates", tags=["candidates"])


@router.get("", response_model=list[CandidateOut])
def candidates(
    session: SessionDep,
    sort: Literal["index", "score"] = "index",
    limit: Annotated[int | None, Query(ge=1)] = None,
    eligible_only: bool = False,
) -> list[dict[str, Any]]:
    """Candidates of the pending (else the last) plan; ``sort=score&limit=10`` gives the top ten."""
    entry = session.plan_for()
    items = [candidate_json(entry.plan, i) for i in range(len(entry.plan.candidates))]
    if eligible_only:
        items = [c for c in items if c["eligible"]]
    if sort == "score":
        items.sort(key=lambda c: (not c["eligible"], -c["score"]))
    return items[:limit] if limit else items


@router.get("/{index}", response_model=CandidateDetail)
def candidate(session: SessionDep, index: int) -> dict[str, Any]:
    """One candidate with its score broken down per ellipsoid."""
    entry = session.plan_for()
    return candidate_detail(entry.plan, entry.plan_id, session.candidate_of(entry, index))


@router.get(
    "/{index}/projection.png",
    response_class=Response,
    responses={200: {"content": {"image/png": {}}}},
)
def projection_png(session: SessionDep, index: int) -> Response:
    """The ellipsoids projected into this candidate's camera (frontier red, occupied blue, fill by weight); for
    ``projection-zbuffer`` its z-buffer raster (visible frontier red, hidden dark red, occupied blue)."""
    from app.scene.projection_image import render_projection, render_zbuffer

    entry = session.plan_for()
    i = session.candidate_of(entry, index)
    if session.evaluator == "projection-zbuffer":  # what its score counts: the z-buffer raster
        config = session.config
        png = render_zbuffer(entry.plan, i, session.cell.intrinsics, config.zbuffer, config.voxel.resolution)
    else:
        png = render_projection(entry.plan, i, session.cell.intrinsics)
    return Response(png, media_type="image/png", headers={"Cache-Control": "no-store"})


routers = [router]
