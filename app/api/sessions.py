"""Sessions as resources: create, list, read, resume, retry, configure, delete, export."""

from __future__ import annotations

from typing import Annotated, Any, Literal

from fastapi import APIRouter, Body, Response
from fastapi.responses import JSONResponse

from app.api.deps import Registry, SessionDep, Settings
from app.schemas import (
    ArmsOut,
    CameraModelsOut,
    DiscardOut,
    ExportOut,
    FaultQueuedOut,
    FaultRequest,
    MetricsOut,
    ResumeOut,
    SessionCreate,
    SessionCreated,
    SessionOut,
)
from app.serialize import SafeJSONResponse
from workbench import Conflict, Invalid, NotFound, arm_choices, camera_models

router = APIRouter(prefix="/sessions", tags=["sessions"])
creations_router = APIRouter(prefix="/creations", tags=["sessions"])
planners_router = APIRouter(prefix="/planners", tags=["sessions"])
sensors_router = APIRouter(prefix="/sensors", tags=["sessions"])
arms_router = APIRouter(prefix="/arms", tags=["sessions"])


@router.post("", status_code=201, response_model=SessionCreated)
def create_session(
    registry: Registry, settings: Settings, body: Annotated[SessionCreate | None, Body()] = None
) -> dict[str, str]:
    """A new session (every field optional: the server's default model, planner config, simulated cell).
    ``faults`` only on a server started with the test flag ``fault_api``."""
    body = body or SessionCreate()
    if body.faults is not None and not settings.fault_api:
        raise Invalid("faults: fault injection is disabled on this server (a test flag: [server] fault_api = true)")
    source = None if body.source is None else body.source.model_dump(exclude_none=True)
    session = registry.create(
        body.model,
        body.config,
        body.seed,
        source=source,
        faults=body.faults,
        planner=body.planner,
        progress_id=body.progress_id,
        camera=None if body.camera is None else body.camera.model_dump(exclude_none=True),
        guided=body.guided,
        arm=body.arm,
        move_capture=body.move_capture,
    )
    return {"id": session.id}


@creations_router.delete("/{progress_id}", status_code=204)
def cancel_create(registry: Registry, progress_id: str) -> None:
    """Cancel the running create named ``progress_id`` (``POST /api/sessions`` answers 409 at its next stage,
    nothing created); 404 when none runs under that name."""
    if not registry.creations.cancel(progress_id):
        raise NotFound(f"create {progress_id!r}: none is running under this progress_id")


@router.post("/{session_id}/discard", response_model=DiscardOut)
def discard_last_view(session: SessionDep) -> dict[str, Any]:
    """Undo the last view: the session is rebuilt from its journal without that frame (journaled as a discard)."""
    return session.discard_last_view() | {"session": session.status()}


@planners_router.get("", response_model=list[str])
def planners() -> list[str]:
    """The view evaluators a session may plan with (``planner`` of ``POST /api/sessions``)."""
    from planner.evaluators import evaluator_names

    return evaluator_names()


@router.get("", response_model=list[SessionOut])
def list_sessions(registry: Registry) -> list[dict[str, Any]]:
    """Live sessions, and journaled ones of an earlier server process (state ``interrupted``)."""
    return registry.list_status()


@router.get("/{session_id}", response_model=SessionOut)
def get_session(session_id: str, registry: Registry) -> dict[str, Any]:
    return registry.status(session_id)


@router.post("/{session_id}/resume", response_model=ResumeOut)
def resume(session_id: str, registry: Registry) -> dict[str, Any]:
    """Rebuild an interrupted session from its journal: the same map and the same pending plan."""
    session, rebuilt = registry.resume(session_id)
    return {
        "session": session.status(),
        "verified": not rebuilt.mismatches,
        "mismatches": rebuilt.mismatches,
        "interrupted": rebuilt.interrupted,
        "dropped": rebuilt.dropped,
    }


@router.post("/{session_id}/retry", response_model=SessionOut)
def retry(session: SessionDep) -> dict[str, Any]:
    """In state error: re-do the failed step (the same move and capture)."""
    session.retry()
    return session.status()


@router.patch("/{session_id}/config", response_model=dict[str, dict[str, Any]])
def change_config(session: SessionDep, body: dict[str, dict[str, Any]]) -> dict[str, Any]:
    """Change ``termination``, ``candidates`` or ``partitions`` of a running session (journaled)."""
    return session.change_config(body)


@router.post("/{session_id}/faults", status_code=202, response_model=FaultQueuedOut)
def inject_fault(settings: Settings, session: SessionDep, body: FaultRequest) -> dict[str, Any]:
    """Test-only (``fault_api``): the next action of the fault's device fails with ``kind``."""
    if not settings.fault_api:
        raise NotFound("fault injection is disabled on this server (fault_api)")
    if session.injector is None:
        raise Conflict(f"session {session.id}: its devices do not inject faults")
    session.injector.inject(body.kind)
    return {"queued": body.kind}


@router.delete("/{session_id}", status_code=204)
def delete_session(session_id: str, registry: Registry) -> Response:
    registry.delete(session_id)
    return Response(status_code=204)


@router.get("/{session_id}/metrics", response_model=MetricsOut)
def metrics(session: SessionDep) -> dict[str, Any]:
    """Per-iteration coverage, point count and plan time; the BIC curves of the last fit."""
    return session.metrics()


@router.get(
    "/{session_id}/cloud.ply",
    response_class=Response,
    responses={200: {"content": {"application/octet-stream": {}}}},
)
def cloud_ply(session: SessionDep) -> Response:
    """The registered, accumulated cloud as binary PLY."""
    from devices.ply import ply_bytes

    return Response(
        ply_bytes(session.planner.cloud),
        media_type="application/octet-stream",
        headers={"Content-Disposition": f'attachment; filename="nbv-{session.id}-cloud.ply"'},
    )


SURFACE_MEDIA = {"ply": "application/octet-stream", "obj": "text/plain", "glb": "model/gltf-binary"}
"""The media type of each surface format."""


@router.get(
    "/{session_id}/surface.ply",
    response_class=Response,
    responses={
        200: {"content": {media: {} for media in SURFACE_MEDIA.values()}},
        409: {"description": "no surface yet (no view captured, or none saw the object)"},
    },
)
def surface_file(session: SessionDep, format: Literal["ply", "obj", "glb"] = "ply") -> Response:
    """The reconstructed surface (TSDF of the registered views, the plate cut away) as binary PLY, or as
    ``?format=obj`` / ``?format=glb``. 409 before there is a surface."""
    return Response(
        session.surface_file(format),
        media_type=SURFACE_MEDIA[format],
        headers={"Content-Disposition": f'attachment; filename="nbv-{session.id}-surface.{format}"'},
    )


@router.get("/{session_id}/export", response_model=ExportOut)
def export(session: SessionDep) -> JSONResponse:
    """The whole session (every pose, plan, decision, override and metric) as JSON."""
    return SafeJSONResponse(
        session.export(), headers={"Content-Disposition": f'attachment; filename="nbv-{session.id}-session.json"'}
    )


@sensors_router.get("", response_model=CameraModelsOut)
def sensors() -> dict[str, list[str]]:
    """The simulated camera's sensor and calibration models a create's ``camera`` may name (the default first)."""
    return camera_models()


@arms_router.get("", response_model=ArmsOut)
def arms() -> dict[str, list[dict[str, Any]]]:
    """The arms a create's ``arm`` may name: the presets (``nbv arms``), then the reach sphere; ``default`` marks
    the server's default arm (the UR5)."""
    return {"arms": arm_choices()}


routers = [router, creations_router, planners_router, sensors_router, arms_router]
