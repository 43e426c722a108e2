"""The server's own routes: health, and where the browser finds the 3D viewer."""

from __future__ import annotations

from typing import Any

from fastapi import APIRouter, Request

from app.api.deps import Settings
from app.schemas import ViewerOut
from app.settings import is_loopback, viewer_host
from workbench.errors import Conflict

router = APIRouter()


@router.get("/health")
def health() -> dict[str, str]:
    return {"status": "ok"}


@router.get("/viewer", response_model=ViewerOut)
def viewer(request: Request, settings: Settings) -> dict[str, Any]:
    """Where the browser finds the viser client: the host the page was loaded from, viser's actual port.

    The URL never carries the API token (it would end up in viser's logs and the browser history); viser
    itself checks nothing: on an exposed server it listens on 127.0.0.1 only (unless ``viser_public``),
    see docs/security.md.
    """
    server = request.app.state.viser
    if server is None:
        raise Conflict("the 3D viewer is disabled on this server")
    port = int(server.get_port())
    host = request.url.hostname or "127.0.0.1"
    note = None
    if is_loopback(viewer_host(settings)) and not is_loopback(host):
        host = "127.0.0.1"
        note = "the 3D viewer has no authentication, so it listens on 127.0.0.1 only: reach it through an SSH tunnel"
    if ":" in host:
        host = f"[{host}]"
    return {"url": f"{request.url.scheme}://{host}:{port}/", "port": port, "note": note}  # never the API token
