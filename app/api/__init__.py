"""The REST API (the paths are a contract with clients; OpenAPI at /docs): one router per resource.

Thin routes: each calls the session (workbench/session/session.py) or the registry and returns a schema object.
Heavy routes are plain ``def`` (FastAPI runs them in its thread pool). Errors are ``{"detail": ...}`` with
400 (bad Host), 401 (token), 403 (cross-origin), 404 (unknown session / candidate / model / recording),
409 (wrong state, stale or used plan_id, an interrupted session not resumed yet), 413 (body too large),
422 (bad parameters, unreachable pose or one inside the object, bad frames from a recording) and 503 (a
device fault or timeout; the session is then in state error, the map unchanged). app/errors.py maps the
domain errors' types to these codes.
"""

from __future__ import annotations

from fastapi import APIRouter

from app.api import (
    arm,
    calibration,
    candidates,
    classes,
    events,
    fit,
    loop,
    models,
    recording,
    scene,
    sessions,
    timeline,
    viewer,
)
from app.schemas import ERROR_RESPONSES

router = APIRouter(prefix="/api", responses=ERROR_RESPONSES)
MODULES = (
    viewer,
    models,
    sessions,
    loop,
    candidates,
    timeline,
    recording,
    scene,
    fit,
    events,
    arm,
    calibration,
    classes,
)
for module in MODULES:
    for resource in module.routers:  # each with its prefix and tags
        router.include_router(resource)
