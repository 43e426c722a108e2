"""Typed dependencies of the routes (``Annotated`` aliases, as in FastAPI's full-stack template)."""

from __future__ import annotations

from collections.abc import Iterator
from typing import Annotated

from fastapi import Depends, Request

from app.scene.controller import SceneController
from app.settings import AppSettings
from workbench import Conflict, Session, SessionRegistry


def registry_of(request: Request) -> SessionRegistry:
    return request.app.state.registry


def settings_of(request: Request) -> AppSettings:
    return request.app.state.settings


def scene_of(request: Request) -> SceneController:
    scene = request.app.state.scene
    if scene is None:
        raise Conflict("the 3D scene is disabled on this server")
    return scene


def session_of(
    session_id: str, registry: Annotated[SessionRegistry, Depends(registry_of)], request: Request
) -> Iterator[Session]:
    """The live session of the path, held live for the whole request (``SessionRegistry.hold``): a sleep never
    cuts off a request in flight (a timeline rebuild, a recording, a step). A change (not GET) of a seat of a
    class the teacher paused is refused (409) before the session is touched."""
    classes = getattr(request.app.state, "classes", None)
    if request.method not in ("GET", "HEAD") and classes is not None and classes.paused(session_id):
        raise Conflict(f"session {session_id}: the teacher paused the class; wait until it is resumed")
    with registry.hold(session_id) as session:
        yield session


Registry = Annotated[SessionRegistry, Depends(registry_of)]
Settings = Annotated[AppSettings, Depends(settings_of)]
SessionDep = Annotated[Session, Depends(session_of)]
Scene = Annotated[SceneController, Depends(scene_of)]
