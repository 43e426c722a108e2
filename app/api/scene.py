"""A tab's 3D viewer: its layers, its camera, what it has drawn (the viewer id comes from ``POST /api/viewer``)."""

from __future__ import annotations

from typing import Any

from fastapi import APIRouter, Response

from app.api.deps import Scene
from app.schemas import CameraRequest, ClientsOut, SceneInfoOut, TimelineRequest, TimelineStepOut, ViewerCameraOut

router = APIRouter(prefix="/scene", tags=["scene"])


@router.get("/cameras", response_model=list[ViewerCameraOut])
def scene_cameras(scene: Scene) -> list[dict[str, Any]]:
    """Each connected viewer's camera (OpenCV pose, vertical fov, canvas size), as last reported."""
    return scene.cameras()


@router.get("/{viewer}", response_model=SceneInfoOut)
def scene_info(scene: Scene, viewer: str) -> dict[str, Any]:
    """The viewer's session, whether it is connected, layer visibility, drawn node names, colour bar."""
    return scene.info(viewer)


@router.put("/{viewer}/layers", response_model=dict[str, bool])
def scene_layers(scene: Scene, viewer: str, body: dict[str, bool]) -> dict[str, bool]:
    """Show or hide layers of this viewer, e.g. ``{"empty": true, "gmm": true}``."""
    return scene.set_layers(viewer, body)


@router.put("/{viewer}/timeline", response_model=TimelineStepOut | None)
def scene_timeline(scene: Scene, viewer: str, body: TimelineRequest) -> dict[str, Any] | None:
    """Show the session after view ``view`` in this viewer (``{"view": null}``: the session now again); the step
    shown, or null. The session is not changed; its events redraw this viewer once it shows now again."""
    step = scene.show_step(viewer, body.view)
    return None if step is None else step.summary()


@router.get("/{viewer}/view.png", response_class=Response, responses={200: {"content": {"image/png": {}}}})
def scene_picture(scene: Scene, viewer: str) -> Response:
    """A PNG of this viewer's 3D view as its tab shows it now (rendered by the browser at its canvas size); 409
    when the viewer is not connected or its browser does not answer."""
    return Response(scene.picture(viewer), media_type="image/png", headers={"Cache-Control": "no-store"})


@router.post("/{viewer}/camera", response_model=ClientsOut)
def scene_camera(scene: Scene, viewer: str, body: CameraRequest) -> dict[str, int]:
    """Point this viewer's camera at a candidate (from outside the hemisphere) or at a given point."""
    if body.candidate is not None:
        return {"clients": scene.look_at_candidate(viewer, body.candidate, body.distance)}
    return {"clients": scene.set_camera(viewer, body.position, body.look_at)}


routers = [router]
