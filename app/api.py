"""The REST API (the paths are a contract of issue 4; OpenAPI at /docs). Thin routes: each calls the Workbench.

Heavy routes are plain ``def`` (FastAPI runs them in its thread pool). Errors are
``{"detail": ...}`` with 400 (bad Host), 401 (token), 403 (cross-origin), 404
(unknown session / candidate / model / recording), 409 (wrong state, stale or used
plan_id, an interrupted session not resumed yet), 413 (body too large), 422 (bad
parameters, unreachable pose or one inside the object, bad frames from a recording)
and 503 (a device fault or timeout; the session is then in state error, the map unchanged).
"""

from __future__ import annotations

from typing import Annotated, Any, Literal

from fastapi import APIRouter, Body, Depends, Query, Request, Response, UploadFile
from fastapi.responses import JSONResponse

from app.errors import ConflictError, NotFoundError, TooLargeError, UnprocessableError
from app.models import list_models, save_upload
from app.scene import SceneController
from app.schemas import (
    ERROR_RESPONSES,
    ApproveRequest,
    AutoRequest,
    CameraRequest,
    CandidateDetail,
    CandidateOut,
    CustomPoseOut,
    CustomPoseRequest,
    FaultRequest,
    FocusRequest,
    ModelOut,
    PlanOut,
    ResumeOut,
    SelectRequest,
    SessionCreate,
    SessionCreated,
    SessionOut,
    StepRequest,
    ViewerOut,
)
from app.serialize import candidate_detail, candidate_json
from app.sessions import SessionRegistry
from app.settings import AppSettings
from app.workbench import Workbench, custom_json, plan_summary

router = APIRouter(prefix="/api", responses=ERROR_RESPONSES)


def registry_of(request: Request) -> SessionRegistry:
    return request.app.state.registry


def scene_of(request: Request) -> SceneController:
    scene = request.app.state.scene
    if scene is None:
        raise ConflictError("the 3D scene is disabled on this server")
    return scene


def session_of(session_id: str, registry: Annotated[SessionRegistry, Depends(registry_of)]) -> Workbench:
    return registry.get(session_id)


Registry = Annotated[SessionRegistry, Depends(registry_of)]
Session = Annotated[Workbench, Depends(session_of)]
Scene = Annotated[SceneController, Depends(scene_of)]


# ---------------------------------------------------------------------- server


@router.get("/health")
def health() -> dict[str, str]:
    return {"status": "ok"}


@router.get("/viewer", response_model=ViewerOut)
def viewer(request: Request) -> dict[str, Any]:
    """Where the browser finds the viser client: the host the page was loaded from, viser's actual port.

    With a token the URL carries it too (``?token=``), but viser itself checks nothing: on an exposed
    server it listens on 127.0.0.1 only (unless ``viser_public``), see docs/security.md.
    """
    from app.main import viewer_host
    from app.settings import is_loopback

    settings: AppSettings = request.app.state.settings
    server = request.app.state.viser
    if server is None:
        raise ConflictError("the 3D viewer is disabled on this server")
    port = int(server.get_port())
    host = request.url.hostname or "127.0.0.1"
    note = None
    if is_loopback(viewer_host(settings)) and not is_loopback(host):
        host = "127.0.0.1"
        note = "the 3D viewer has no authentication, so it listens on 127.0.0.1 only: reach it through an SSH tunnel"
    if ":" in host:
        host = f"[{host}]"
    query = f"?token={settings.token}" if settings.token else ""
    return {"url": f"{request.url.scheme}://{host}:{port}/{query}", "port": port, "note": note}


@router.get("/models", response_model=list[ModelOut])
def models(request: Request) -> list[dict[str, Any]]:
    """Built-in objects, mesh files in the models directory, and uploads."""
    settings: AppSettings = request.app.state.settings
    return [m.to_json() for m in list_models(settings)]


@router.post("/models", status_code=201, response_model=ModelOut)
def upload_model(request: Request, file: UploadFile) -> dict[str, Any]:
    """Upload a mesh (PLY/OBJ/STL/OFF/GLB); it is checked, stored under the data directory and listed."""
    settings: AppSettings = request.app.state.settings
    data = file.file.read(settings.max_upload_bytes + 1)
    if len(data) > settings.max_upload_bytes:
        raise TooLargeError(f"upload: over the limit of {settings.max_upload_bytes} bytes")
    return save_upload(settings, file.filename or "upload", data).to_json()


# ---------------------------------------------------------------------- sessions


@router.get("/recordings", response_model=list[str])
def recordings(request: Request) -> list[str]:
    """Recording folders (PLY + pose JSON per view) in ``data_dir/recordings``, usable as a replay source."""
    from app.session_factory import list_recordings

    return list_recordings(request.app.state.settings)


@router.post("/sessions", status_code=201, response_model=SessionCreated)
def create_session(registry: Registry, body: Annotated[SessionCreate | None, Body()] = None) -> dict[str, str]:
    """A new session (every field optional: the server's default model, planner config, simulated cell)."""
    body = body or SessionCreate()
    source = None if body.source is None else body.source.model_dump(exclude_none=True)
    wb = registry.create(body.model, body.config, body.seed, source=source, faults=body.faults)
    return {"id": wb.id}


@router.get("/sessions", response_model=list[SessionOut])
def list_sessions(registry: Registry) -> list[dict[str, Any]]:
    """Live sessions, and journaled ones of an earlier server process (state ``interrupted``)."""
    return registry.list_status()


@router.get("/sessions/{session_id}", response_model=SessionOut)
def get_session(session_id: str, registry: Registry) -> dict[str, Any]:
    return registry.status(session_id)


@router.post("/sessions/{session_id}/resume", response_model=ResumeOut)
def resume(session_id: str, registry: Registry) -> dict[str, Any]:
    """Rebuild an interrupted session from its journal: the same map and the same pending plan."""
    wb, rebuilt = registry.resume(session_id)
    return {
        "session": wb.status(),
        "verified": not rebuilt.mismatches,
        "mismatches": rebuilt.mismatches,
        "interrupted": rebuilt.interrupted,
    }


@router.post("/sessions/{session_id}/retry", response_model=SessionOut)
def retry(wb: Session) -> dict[str, Any]:
    """In state error: re-do the failed step (the same move and capture)."""
    wb.retry()
    return wb.status()


@router.patch("/sessions/{session_id}/config")
def change_config(wb: Session, body: dict[str, dict[str, Any]]) -> dict[str, Any]:
    """Change ``termination``, ``candidates`` or ``partitions`` of a running session (journaled)."""
    return wb.change_config(body)


@router.post("/sessions/{session_id}/faults", status_code=202)
def inject_fault(request: Request, wb: Session, body: FaultRequest) -> dict[str, Any]:
    """Test-only (``fault_api``): the next action of the fault's device fails with ``kind``."""
    if not request.app.state.settings.fault_api:
        raise NotFoundError("fault injection is disabled on this server (fault_api)")
    if wb.injector is None:
        raise ConflictError(f"session {wb.id}: its devices do not inject faults")
    wb.injector.inject(body.kind)
    return {"queued": body.kind}


@router.delete("/sessions/{session_id}", status_code=204)
def delete_session(session_id: str, registry: Registry) -> Response:
    registry.delete(session_id)
    return Response(status_code=204)


@router.post("/sessions/{session_id}/capture", response_model=SessionOut)
def capture(wb: Session) -> dict[str, Any]:
    """Capture and integrate the first view at the cell's initial pose (state new -> ready)."""
    wb.capture()
    return wb.status()


@router.post("/sessions/{session_id}/plan", response_model=PlanOut)
def plan(wb: Session) -> dict[str, Any]:
    """Make a new plan; any older pending plan_id goes stale."""
    return plan_summary(wb.plan())


@router.get("/sessions/{session_id}/candidates", response_model=list[CandidateOut])
def candidates(
    wb: Session,
    sort: Literal["index", "score"] = "index",
    limit: Annotated[int | None, Query(ge=1)] = None,
    eligible_only: bool = False,
) -> list[dict[str, Any]]:
    """Candidates of the pending (else the last) plan; ``sort=score&limit=10`` gives the top ten."""
    entry = wb.plan_for()
    items = [candidate_json(entry.plan, i) for i in range(len(entry.plan.candidates))]
    if eligible_only:
        items = [c for c in items if c["eligible"]]
    if sort == "score":
        items.sort(key=lambda c: (not c["eligible"], -c["score"]))
    return items[:limit] if limit else items


@router.get("/sessions/{session_id}/candidates/{index}", response_model=CandidateDetail)
def candidate(wb: Session, index: int) -> dict[str, Any]:
    """One candidate with its score broken down per ellipsoid."""
    entry = wb.plan_for()
    return candidate_detail(entry.plan, entry.plan_id, wb.candidate_of(entry, index))


@router.get(
    "/sessions/{session_id}/candidates/{index}/projection.png",
    response_class=Response,
    responses={200: {"content": {"image/png": {}}}},
)
def projection_png(wb: Session, index: int) -> Response:
    """The ellipsoids projected into this candidate's camera: frontier red, occupied blue, fill by weight."""
    from app.projection_image import render_projection

    entry = wb.plan_for()
    png = render_projection(entry.plan, wb.candidate_of(entry, index), wb.cell.intrinsics)
    return Response(png, media_type="image/png", headers={"Cache-Control": "no-store"})


@router.put("/sessions/{session_id}/selection", response_model=SessionOut)
def select(wb: Session, body: SelectRequest) -> dict[str, Any]:
    """Highlight a candidate of the pending plan (the page's list and a click in the 3D scene both do this)."""
    wb.select(body.index)
    return wb.status()


@router.put("/sessions/{session_id}/custom_pose", response_model=CustomPoseOut)
def custom_pose(wb: Session, body: CustomPoseRequest) -> dict[str, Any]:
    """Propose a custom view (as the gizmo does); the answer says whether the cell can reach it."""
    return custom_json(wb.set_custom(body.pose.to_pose()))


@router.post("/sessions/{session_id}/approve", response_model=SessionOut)
def approve(wb: Session, body: ApproveRequest) -> dict[str, Any]:
    """Move to the approved view, capture, integrate. 409 stale/used plan_id, 422 unreachable: nothing moves."""
    pose = body.pose.to_pose() if body.pose is not None else None
    wb.approve(body.plan_id, index=body.index, pose=pose)
    return wb.status()


@router.post("/sessions/{session_id}/step", response_model=SessionOut)
def step(wb: Session, body: Annotated[StepRequest | None, Body()] = None) -> dict[str, Any]:
    """Plan and approve the planner's choice, ``count`` times (for scripts)."""
    wb.step((body or StepRequest()).count)
    return wb.status()


@router.post("/sessions/{session_id}/auto", status_code=202, response_model=SessionOut)
def auto(wb: Session, body: Annotated[AutoRequest | None, Body()] = None) -> dict[str, Any]:
    """Start auto mode: up to ``count`` steps in the background; POST .../stop ends it."""
    wb.start_auto((body or AutoRequest()).count)
    return wb.status()


@router.post("/sessions/{session_id}/stop", response_model=SessionOut)
def stop(wb: Session) -> dict[str, Any]:
    """Stop auto mode after the current action."""
    wb.stop()
    return wb.status()


@router.get("/sessions/{session_id}/metrics")
def metrics(wb: Session) -> dict[str, Any]:
    """Per-iteration coverage, point count and plan time; the BIC curves of the last fit."""
    return wb.metrics()


@router.get(
    "/sessions/{session_id}/cloud.ply",
    response_class=Response,
    responses={200: {"content": {"application/octet-stream": {}}}},
)
def cloud_ply(wb: Session) -> Response:
    """The registered, accumulated cloud as binary PLY."""
    from devices.ply import ply_bytes

    return Response(
        ply_bytes(wb.planner.cloud),
        media_type="application/octet-stream",
        headers={"Content-Disposition": f'attachment; filename="nbv-{wb.id}-cloud.ply"'},
    )


@router.get("/sessions/{session_id}/export")
def export(wb: Session) -> JSONResponse:
    """The whole session (every pose, plan, decision, override and metric) as JSON."""
    from app.serialize import SafeJSONResponse

    return SafeJSONResponse(
        wb.export(), headers={"Content-Disposition": f'attachment; filename="nbv-{wb.id}-session.json"'}
    )


# ---------------------------------------------------------------------- the 3D scene


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
    try:
        return scene.set_layers(body)
    except ValueError as exc:
        raise UnprocessableError(str(exc)) from None


@router.post("/scene/camera")
def scene_camera(scene: Scene, body: CameraRequest) -> dict[str, int]:
    """Point every viewer's camera at a candidate (from outside the hemisphere) or at a given point."""
    try:
        if body.candidate is not None:
            n = scene.look_at_candidate(body.candidate, body.distance)
        else:
            n = scene.set_camera(body.position, body.look_at)
    except ValueError as exc:
        if "out of range" in str(exc):
            raise NotFoundError(str(exc)) from None
        raise ConflictError(str(exc)) from None
    return {"clients": n}


@router.get("/scene/cameras")
def scene_cameras(scene: Scene) -> list[dict[str, Any]]:
    """Each connected viewer's camera (OpenCV pose, vertical fov, canvas size), as last reported."""
    return scene.cameras()
