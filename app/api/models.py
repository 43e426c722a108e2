"""The objects a session can scan (built-ins, model files, uploads) and the replay recordings."""

from __future__ import annotations

from typing import Any

from fastapi import APIRouter, UploadFile

from app.api.deps import Settings
from app.schemas import ModelOut
from workbench import TooLarge, list_models, list_recorded, list_recordings, save_upload

router = APIRouter(prefix="/models", tags=["catalog"])
recordings_router = APIRouter(prefix="/recordings", tags=["catalog"])
recorded_router = APIRouter(prefix="/recorded", tags=["catalog"])


@router.get("", response_model=list[ModelOut])
def models(settings: Settings) -> list[dict[str, Any]]:
    """Built-in objects, mesh files in the models directory, and uploads."""
    return [m.to_json() for m in list_models(settings)]


@router.post("", status_code=201, response_model=ModelOut)
def upload_model(settings: Settings, file: UploadFile) -> dict[str, Any]:
    """Upload a mesh (PLY/OBJ/STL/OFF/GLB); it is checked, stored under the data directory and listed."""
    data = file.file.read(settings.max_upload_bytes + 1)
    if len(data) > settings.max_upload_bytes:
        raise TooLarge(f"upload: over the limit of {settings.max_upload_bytes} bytes")
    return save_upload(settings, file.filename or "upload", data).to_json()


@recordings_router.get("", response_model=list[str])
def recordings(settings: Settings) -> list[str]:
    """Recording folders (PLY + pose JSON per view) in ``data_dir/recordings``, usable as a replay source."""
    return list_recordings(settings)


@recorded_router.get("", response_model=list[str])
def recorded(settings: Settings) -> list[str]:
    """Recorded view sets in ``data_dir/recorded`` (``views.json`` folders or Stanford range scans), usable as a
    ``recorded`` source: the planner chooses among their views."""
    return list_recorded(settings)


routers = [router, recordings_router, recorded_router]
