"""A session's recording: a zip that plays the scan offline (app/scene/recording.py), from its timeline."""

from __future__ import annotations

from typing import Annotated

from fastapi import APIRouter, Query, Response

from app.api.deps import SessionDep
from app.scene.recording import STEP_SECONDS, build_recording
from workbench import Conflict

router = APIRouter(prefix="/sessions/{session_id}/recording", tags=["recording"])


@router.get("", response_class=Response, responses={200: {"content": {"application/zip": {}}}})
def recording(session: SessionDep, step_seconds: Annotated[float, Query(gt=0.0, le=60.0)] = STEP_SECONDS) -> Response:
    """The scan as a zip, its files in one folder ``nbv-ID-recording/`` (``index.html``: viser's client with the scene embedded, one step per view, plus
    ``scene.viser`` and ``steps.json``) that plays from its unzipped folder or any static host, offline. 409
    without a journal or a view. ``step_seconds``: playback time per view."""
    steps = session.history.steps()
    if not steps:
        raise Conflict(f"session {session.id}: no view yet to record")
    folder = f"nbv-{session.id}-recording"
    title = f"NBV scan {session.id} · {session.status()['model']}"
    built = build_recording(steps, session.scene_data(), title, step_seconds, folder=folder)
    return Response(
        built.data,
        media_type="application/zip",
        headers={
            "Content-Disposition": f'attachment; filename="{folder}.zip"',
            "Cache-Control": "no-store",
        },
    )


routers = [router]
