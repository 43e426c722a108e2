"""Pushed events: a websocket per tab (``/api/events?session=ID``) instead of polling.

Messages (JSON):

- ``{"type": "status", "event": "state"|"planned"|"captured"|"selection"|"custom_pose", "status": {...}}``:
  the session's status (the shape of ``GET /api/sessions/{id}``) after each change, first on connect;
- ``{"type": "sessions", "change": "created"|"deleted", "id": ...}``: the session list changed;
- ``{"type": "sessions", "change": "state", "id": ..., "session": {...}}``: a session of the list changed its
  state or took a view (``session``: its status, the shape of the list's entries), so a picker stays current;
- ``{"type": "deleted"}``: this tab's session was deleted;
- ``{"type": "progress", "progress": {...} | null}``: the session's long operation (a plan, a discard, its
  resume) moved on or ended (``ProgressOut``; at most ten a second within a stage);
- ``{"type": "viewer", "viewer": ID, "layers": {...}, "focus": "O3" | null, "refits": {kind: T}, "view": j | null}``: a viewer of
  this session changed (its layers, however set, its focused ellipsoid, a fit at another T); a page keeps the
  ones of its own viewer (app/scene/fit_view.py);
- with ``?create=ID`` (a ``progress_id`` of ``POST /api/sessions``): ``{"type": "create", "id": ID,
  "progress": {...} | null}`` as that create goes (null: it ended).

Browsers cannot set headers on a websocket, so the token (when the server has one) comes as ``?token=``;
the Origin must be the page's own or one of ``cors_origins`` (app/security.py checks plain HTTP only).
A refused socket is closed with 4401 (token) or 4403 (origin), an unknown session with 4404.
"""

from __future__ import annotations

import asyncio
import contextlib
import hmac
import json
import logging
from typing import Any

from fastapi import APIRouter, WebSocket, WebSocketDisconnect

from app.security import same_origin
from app.settings import AppSettings
from workbench import Conflict, Progress, Session, SessionEvent, WorkbenchError, jsonable, resume_id

router = APIRouter(prefix="/events", tags=["events"])
LIST_EVENTS = frozenset({SessionEvent.STATE, SessionEvent.CAPTURED})
"""A session's events that change its entry in the session list (state, views, coverage)."""
log = logging.getLogger(__name__)


def refusal(ws: WebSocket, settings: AppSettings) -> tuple[int, str] | None:
    """(close code, reason) when this websocket may not subscribe, else None."""
    origin = ws.headers.get("origin")
    host = ws.headers.get("host", "")
    if origin is not None and not same_origin(origin, host, settings.cors_origins):
        return 4403, f"cross-origin event stream from {origin!r} refused"
    if settings.token:
        given = ws.query_params.get("token", "")
        if not hmac.compare_digest(given.encode("utf-8"), settings.token.encode("utf-8")):
            return 4401, "missing or wrong token"
    return None


def _dump(message: dict[str, Any]) -> str:
    """JSON text the way the REST answers are encoded (NaN-safe)."""
    return json.dumps(jsonable(message), separators=(",", ":"))


@router.websocket("")
async def events(ws: WebSocket, session: str | None = None, create: str | None = None) -> None:
    """Push the session's status after every change and the session list's changes (see the module docstring)."""
    settings: AppSettings = ws.app.state.settings
    registry = ws.app.state.registry
    refused = refusal(ws, settings)
    if refused is not None:
        await ws.close(code=refused[0], reason=refused[1])
        return
    live: Session | None = None
    first: dict[str, Any] | None = None
    if session is not None:
        try:
            first = registry.status(session)  # an interrupted session has a status too (state "interrupted")
            live = registry.get(session)
        except Conflict:
            live = None  # interrupted: followed once it is resumed
        except WorkbenchError as exc:
            await ws.accept()
            await ws.send_text(json.dumps({"type": "error", "detail": exc.detail}))
            await ws.close(code=4404, reason="unknown session")
            return
    await ws.accept()
    loop = asyncio.get_running_loop()
    queue: asyncio.Queue[dict[str, Any]] = asyncio.Queue()

    def push(message: dict[str, Any]) -> None:
        loop.call_soon_threadsafe(queue.put_nowait, message)

    def on_session(s: Session, event: SessionEvent) -> None:
        if event == SessionEvent.PROGRESS:
            push({"type": "progress", "progress": s.progress_json()})
        else:
            push({"type": "status", "event": str(event), "status": s.status()})

    def on_create_progress(progress_id: str, progress: Progress | None) -> None:
        value = None if progress is None else progress.to_json()
        if progress_id == create:
            push({"type": "create", "id": progress_id, "progress": value})
        elif session is not None and progress_id == resume_id(session):  # this tab's session being resumed
            push({"type": "progress", "progress": value})

    def on_listed(s: Session, event: SessionEvent) -> None:
        if event in LIST_EVENTS:
            push({"type": "sessions", "change": "state", "id": s.id, "session": s.status()})

    def on_create(s: Session) -> None:
        nonlocal live
        s.listeners.append(on_listed)
        push({"type": "sessions", "change": "created", "id": s.id})
        if s.id == session and live is not s:  # resumed or woken: follow it from now on
            live = s
            s.listeners.append(on_session)
            push({"type": "status", "event": "state", "status": s.status()})

    def on_delete(s: Session) -> None:
        push({"type": "sessions", "change": "deleted", "id": s.id})
        if live is not None and s.id == live.id:
            push({"type": "deleted"})

    def on_viewer(session_id: str, message: dict[str, Any]) -> None:
        if session_id == session:
            push(message)

    scene = ws.app.state.scene
    if scene is not None:
        scene.viewer_listeners.append(on_viewer)
    if live is not None:
        live.listeners.append(on_session)
    listed = registry.list()
    for s in listed:
        s.listeners.append(on_listed)
    registry.on_create.append(on_create)
    registry.on_delete.append(on_delete)
    registry.creations.listeners.append(on_create_progress)
    if create is not None and (current := registry.creations.progress(create)) is not None:
        push({"type": "create", "id": create, "progress": current.to_json()})
    reader = asyncio.create_task(_drain(ws))
    try:
        if first is not None:
            await ws.send_text(_dump({"type": "status", "event": "state", "status": first}))
        while not reader.done():
            getter = asyncio.ensure_future(queue.get())
            done, _ = await asyncio.wait({getter, reader}, return_when=asyncio.FIRST_COMPLETED)
            if getter not in done:
                getter.cancel()
                break
            await ws.send_text(_dump(getter.result()))
    except (WebSocketDisconnect, RuntimeError):
        pass
    finally:
        reader.cancel()
        with contextlib.suppress(ValueError):
            registry.on_create.remove(on_create)
        with contextlib.suppress(ValueError):
            registry.on_delete.remove(on_delete)
        with contextlib.suppress(ValueError):
            registry.creations.listeners.remove(on_create_progress)
        if scene is not None:
            with contextlib.suppress(ValueError):
                scene.viewer_listeners.remove(on_viewer)
        if live is not None:
            with contextlib.suppress(ValueError):
                live.listeners.remove(on_session)
        for s in registry.list() + listed:
            with contextlib.suppress(ValueError):
                s.listeners.remove(on_listed)


async def _drain(ws: WebSocket) -> None:
    """Read (and ignore) what the page sends until it disconnects."""
    with contextlib.suppress(WebSocketDisconnect, RuntimeError):
        while True:
            message = await ws.receive()
            if message["type"] == "websocket.disconnect":
                return


routers = [router]
