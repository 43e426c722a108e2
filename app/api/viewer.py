"""The server's own routes: health, and the 3D viewer of a tab (a single-use ticket bound to one session)."""

from __future__ import annotations

from typing import Any

from fastapi import APIRouter, Request

from app.api.deps import Registry, Scene, Settings
from app.scene.controller import SceneController
from app.scene.guard import viewer_url
from app.scene.preview import PREVIEW_KEY
from app.schemas import HealthOut, ViewerOut, ViewerRequest, ViewerTicketOut
from app.settings import AppSettings, is_loopback, viewer_host
from workbench import Conflict

health_router = APIRouter(prefix="/health", tags=["server"])
router = APIRouter(prefix="/viewer", tags=["viewer"])


@health_router.get("", response_model=HealthOut)
def health() -> dict[str, str]:
    return {"status": "ok"}


def _where(request: Request, settings: AppSettings) -> tuple[str, int, str | None]:
    """(host, port, note): the viser server as the browser reaches it (the host the page was loaded from)."""
    server = request.app.state.viser
    if server is None:
        raise Conflict("the 3D viewer is disabled on this server")
    port = int(server.get_port())
    host = request.url.hostname or "127.0.0.1"
    note = None
    if is_loopback(viewer_host(settings)) and not is_loopback(host):
        host = "127.0.0.1"
        note = "the 3D viewer listens on 127.0.0.1 only on this server: reach it through an SSH tunnel"
    if ":" in host:
        host = f"[{host}]"
    return host, port, note


@router.get("", response_model=ViewerOut)
def viewer(request: Request, settings: Settings) -> dict[str, Any]:
    """Where the viser client is served. Without a ticket (``POST /api/viewer``) it shows an empty scene."""
    host, port, note = _where(request, settings)
    return {"url": viewer_url(request.url.scheme, host, port, None), "port": port, "note": note}


@router.post("", response_model=ViewerTicketOut, status_code=201)
def open_viewer(
    request: Request, settings: Settings, scene: Scene, registry: Registry, body: ViewerRequest
) -> dict[str, Any]:
    """A viewer of ``session`` for one tab: its URL carries a single-use, short-lived ticket that binds the
    viewer's websocket to this session (the viewer's Origin is checked too)."""
    return viewer_ticket(request, settings, scene, registry.get(body.session).id)


@router.post("/preview", response_model=ViewerTicketOut, status_code=201)
def open_preview(request: Request, settings: Settings, scene: Scene) -> dict[str, Any]:
    """A viewer of no session, for a tab that has none open (the first screen): the simulated cell and the server's
    default object as a demo scan would start from (app/scene/preview.py). Its ``session`` is ``"preview"``;
    nothing is created or journaled."""
    return viewer_ticket(request, settings, scene, PREVIEW_KEY)


def viewer_ticket(
    request: Request, settings: AppSettings, scene: SceneController, key: str, readonly: bool = False
) -> dict[str, Any]:
    """A new viewer of ``key`` (a session's id, or a calibration's) as the routes answer it; ``readonly``: its
    clicks and gizmo change nothing (a class seat on the projector)."""
    host, port, note = _where(request, settings)
    ticket = scene.open_viewer_of(key, readonly=readonly)
    return {
        "viewer": ticket.viewer,
        "session": key,
        "url": viewer_url(request.url.scheme, host, port, ticket.secret),
        "port": port,
        "ttl": scene.tickets.ttl,
        "note": note,
    }


routers = [health_router, router]
