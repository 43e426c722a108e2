"""Class mode (docs/class.md): a teacher's class of seats, each an ordinary session; join by code; the board."""

from __future__ import annotations

import io
from typing import Annotated, Any

from fastapi import APIRouter, Depends, Request, Response

from app.api.deps import Registry, Scene, Settings
from app.api.viewer import viewer_ticket
from app.schemas import BoardOut, ClassCreate, ClassOut, JoinOut, JoinRequest, PauseRequest, ViewerTicketOut
from workbench import Classes, ClassRoom, Conflict

router = APIRouter(prefix="/classes", tags=["classes"])


def classes_of(request: Request) -> Classes:
    classes = request.app.state.classes
    if classes is None:
        raise Conflict("class mode is not running on this server")
    return classes


ClassesDep = Annotated[Classes, Depends(classes_of)]


def class_json(room: ClassRoom, classes: Classes) -> dict[str, Any]:
    return {
        "id": room.id,
        "code": room.code,
        "join": f"/join/{room.code}",
        "planner": room.planner,
        "models": list(room.models),
        "guided": room.guided,
        "paused": room.paused,
        "live_limit": classes.registry.live_limit(),
        "seats": [
            {"seat": s.number, "session": s.session, "model": s.model, "joined": s.joined, "resets": s.resets}
            for s in room.seats
        ],
    }


@router.post("", status_code=201, response_model=ClassOut)
def create_class(classes: ClassesDep, body: ClassCreate) -> dict[str, Any]:
    """A class of ``seats`` new sessions (all made before this answers; 422 with nothing created for 0 seats,
    more than ``max_class_seats``, an unknown model or planner). The live limit rises to hold the seats."""
    models = body.model if isinstance(body.model, list) else None if body.model is None else [body.model]
    room = classes.create(body.seats, models, body.planner, body.guided, body.config)
    return class_json(room, classes)


@router.get("", response_model=list[ClassOut])
def list_classes(classes: ClassesDep) -> list[dict[str, Any]]:
    return [class_json(room, classes) for room in classes.list()]


@router.post("/join", response_model=JoinOut, response_model_by_alias=True)
def join(classes: ClassesDep, settings: Settings, body: JoinRequest) -> dict[str, Any]:
    """A student joins with the code: the next free seat (or ``seat`` again); the answer names its session."""
    room, seat = classes.join(body.code, body.seat)
    return {
        "class": room.id,
        "seat": seat.number,
        "session": seat.session,
        "guided": room.guided,
        "url": f"/?session={seat.session}",
    }


@router.get("/{class_id}", response_model=BoardOut)
def board(classes: ClassesDep, class_id: str) -> dict[str, Any]:
    """The board: every seat's state, views, coverage, and whether it sleeps (reading it wakes no seat)."""
    return classes.board(class_id) | {"join": f"/join/{classes.get(class_id).code}"}


@router.delete("/{class_id}", status_code=204)
def delete_class(classes: ClassesDep, class_id: str) -> Response:
    """Forget the class and delete its seats' sessions."""
    classes.delete(class_id)
    return Response(status_code=204)


@router.post("/{class_id}/pause", response_model=BoardOut)
def pause(classes: ClassesDep, class_id: str, body: PauseRequest) -> dict[str, Any]:
    """``{"paused": true}``: every seat stops (auto mode, a plan) and refuses changes (409) until
    ``{"paused": false}``; reads still answer."""
    room = classes.pause(class_id, body.paused)
    return classes.board(class_id) | {"join": f"/join/{room.code}"}


@router.post("/{class_id}/seats/{seat}/reset", response_model=ClassOut)
def reset_seat(classes: ClassesDep, class_id: str, seat: int) -> dict[str, Any]:
    """Seat ``seat`` starts again with a new session (the old one is deleted); its student rejoins the seat."""
    classes.reset(class_id, seat)
    return class_json(classes.get(class_id), classes)


@router.get(
    "/{class_id}/seats/{seat}/picture.png", response_class=Response, responses={200: {"content": {"image/png": {}}}}
)
def seat_picture(classes: ClassesDep, class_id: str, seat: int) -> Response:
    """A small picture of the seat's cloud (a sleeping seat: its last one; 404 before its first view)."""
    return Response(classes.picture(class_id, seat), media_type="image/png", headers={"Cache-Control": "no-store"})


@router.post("/{class_id}/seats/{seat}/watch", status_code=201, response_model=ViewerTicketOut)
def watch_seat(
    request: Request,
    settings: Settings,
    scene: Scene,
    registry: Registry,
    classes: ClassesDep,
    class_id: str,
    seat: int,
) -> dict[str, Any]:
    """A read-only 3D viewer of the seat (for the projector): clicks and the gizmo in it change nothing."""
    session = registry.get(classes.get(class_id).seat(seat).session)
    return viewer_ticket(request, settings, scene, session.id, readonly=True)


@router.get("/{class_id}/qr.svg", response_class=Response, responses={200: {"content": {"image/svg+xml": {}}}})
def join_qr(request: Request, settings: Settings, classes: ClassesDep, class_id: str) -> Response:
    """The join page's URL as a QR code, for the address the board was opened at (with the server's token when
    it has one: whoever scans it can use the API, as with the token itself)."""
    import segno

    url = join_url(request, settings, classes.get(class_id).code)
    out = io.BytesIO()
    segno.make(url, error="m").save(out, kind="svg", scale=6, border=2, dark="#111", light="#fff")
    return Response(out.getvalue(), media_type="image/svg+xml", headers={"Cache-Control": "no-store"})


def join_url(request: Request, settings: Any, code: str) -> str:
    """The absolute join URL students open (the host the teacher's page reached; the token when set)."""
    base = str(request.base_url).rstrip("/")
    return f"{base}/join/{code}" + (f"?token={settings.token}" if settings.token else "")


routers = [router]
