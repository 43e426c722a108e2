"""The 3D scene: which session it shows, its layers, the viewers' cameras."""

from __future__ import annotations

from typing import Any

from fastapi import APIRouter

from app.api.deps import Registry, Scene
from app.schemas import CameraRequest, FocusRequest

router = APIRouter()


@router.get("/scene")
def scene_info(scene: Scene) -> dict[str, Any]:
    """Focused session, layer visibility, drawn node names, colour bar (stops and score range)."""
    return scene.info()


@router.put("/scene")
def scene_focus(scene: Scene, registry: Registry, body: FocusRequest) -> dict[str, Any]:
    """Choose the session the 3D view shows."""
    scene.focus(None if body.session is None else registry.get(body.session))
    return scene.info()


@router.put("/scene/layers")
def scene_layers(scene: Scene, body: dict[str, bool]) -> dict[str, bool]:
    """Show or hide layers, e.g. ``{"empty": true, "gmm": true}``."""
    return scene.set_layers(body)


@router.post("/scene/camera")
def scene_camera(scene: Scene, body: CameraRequest) -> dict[str, int]:
    """Point every viewer's camera at a candidate (from outside the hemisphere) or at a given point."""
    if body.candidate is not None:
        return {"clients": scene.look_at_candidate(body.candidate, body.distance)}
    return {"clients": scene.set_camera(body.position, body.look_at)}


@router.get("/scene/cameras")
def scene_cameras(scene: Scene) -> list[dict[str, Any]]:
    """Each connected viewer's camera (OpenCV pose, vertical fov, canvas size), as last reported."""
    return scene.cameras()
