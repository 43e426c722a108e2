"""The FastAPI application: REST API, the static page, and (in the lifespan) the viser server.

``create_app(settings)`` builds the app; nothing starts until its lifespan runs
(uvicorn, or ``with TestClient(create_app(settings)) as client``). The lifespan
starts one viser server on ``settings.viser_port`` (viser moves to the next free
port when it is taken; ``GET /api/viewer`` reports the real one), gives each
browser tab's viewer its own scene of one session (app/scene/controller.py), and
on shutdown stops auto modes and viser.

``create_app`` refuses (ValueError) a non-loopback host without a token. Every
request passes app/security.py first; CORS is installed only when configured.
"""

from __future__ import annotations

import logging
import secrets
from collections.abc import AsyncIterator
from contextlib import asynccontextmanager
from pathlib import Path
from typing import Any

from fastapi import FastAPI, Request
from fastapi.encoders import jsonable_encoder
from fastapi.exception_handlers import http_exception_handler
from fastapi.exceptions import RequestValidationError
from fastapi.responses import FileResponse, JSONResponse
from fastapi.staticfiles import StaticFiles
from starlette.exceptions import HTTPException as StarletteHTTPException

from app.api import router
from app.docs_ui import install_docs
from app.errors import status_of
from app.scene.calibration import CalibrationViews
from app.scene.controller import SceneController
from app.scene.preview import PreviewViews
from app.schemas import document_error_bodies
from app.security import SecurityMiddleware, install_log_redaction, openapi_security
from app.serialize import SafeJSONResponse
from app.settings import AppSettings, check_exposure, viewer_host
from workbench import Calibrations, Classes, SessionRegistry, WorkbenchError

STATIC_DIR = Path(__file__).resolve().parent / "static"
log = logging.getLogger(__name__)


def allowed_methods(app: FastAPI, path: str) -> list[str]:
    """The methods some route of ``app`` answers on ``path`` (the ``Allow`` header of a 405)."""
    methods: set[str] = set()
    for route in app.routes:
        regex, route_methods = getattr(route, "path_regex", None), getattr(route, "methods", None)
        if regex is not None and route_methods and regex.match(path):
            methods |= set(route_methods)
    return sorted(methods)


def create_app(settings: AppSettings | None = None) -> FastAPI:
    """The workbench app for ``settings`` (defaults: 127.0.0.1:8000, viser on 8080, model l-block)."""
    settings = settings or AppSettings()
    check_exposure(settings)
    if settings.devices.cell.kinematics == "urdf":  # a bad URDF, SRDF or flange frame fails here, in one line
        from devices.arm.model import check_arm

        check_arm(settings.devices.cell.arm)
    install_log_redaction()

    @asynccontextmanager
    async def lifespan(app: FastAPI) -> AsyncIterator[None]:
        registry = SessionRegistry(settings)
        app.state.classes = Classes(registry)  # class mode: app/api/classes.py (its seats are sessions)
        server = None
        scene = None
        if settings.scene:
            import viser

            server = viser.ViserServer(
                host=viewer_host(settings), port=settings.viser_port, verbose=settings.viser_verbose
            )
            scene = SceneController(server, registry, allowed_origins=settings.cors_origins)
            log.info("viser on port %d", server.get_port())
        app.state.registry = registry
        app.state.viser = server
        app.state.scene = scene
        app.state.calibrations = calibrations = Calibrations(settings)  # calibrate mode: app/api/calibration.py
        app.state.calibration_views = None if scene is None else CalibrationViews(scene, calibrations)
        app.state.preview_views = None if scene is None else PreviewViews(scene, settings)  # the first screen's
        try:
            yield
        finally:
            calibrations.close_all()
            registry.close()
            if server is not None:
                server.stop()

    app = FastAPI(
        title="NBV workbench",
        version="0.1.0",
        description="Supervised next-best-view scanning: plan, inspect, override, approve.",
        lifespan=lifespan,
        default_response_class=SafeJSONResponse,
        docs_url=None,
        redoc_url=None,
    )
    app.state.settings = settings
    app.state.registry = None
    app.state.viser = None
    app.state.scene = None
    app.state.classes = None

    @app.exception_handler(WorkbenchError)
    async def _workbench_error(request: Request, exc: WorkbenchError) -> JSONResponse:
        return JSONResponse({"detail": exc.detail}, status_code=status_of(exc))

    @app.exception_handler(StarletteHTTPException)
    async def _http_error(request: Request, exc: StarletteHTTPException) -> Any:
        if exc.status_code == 405:  # Allow: every method of the path, not only those of the first route matched
            exc.headers = {**(exc.headers or {}), "Allow": ", ".join(allowed_methods(app, request.url.path))}
        return await http_exception_handler(request, exc)

    @app.exception_handler(Exception)
    async def _unexpected(request: Request, exc: Exception) -> JSONResponse:
        # anything not foreseen: JSON, never text/plain, with an id that finds the traceback in the log
        error_id = secrets.token_hex(6)
        log.error(
            "error %s on %s %s: %s: %s",
            error_id,
            request.method,
            request.url.path,
            type(exc).__name__,
            exc,
            exc_info=exc,
        )
        detail = f"internal error {error_id} ({type(exc).__name__}); the server log has the details"
        return JSONResponse({"detail": detail, "error_id": error_id}, status_code=500)

    @app.exception_handler(RequestValidationError)
    async def _validation_error(request: Request, exc: RequestValidationError) -> JSONResponse:
        # like FastAPI's own handler, but a NaN in the rejected input must not turn the 422 into a 500
        return SafeJSONResponse({"detail": jsonable_encoder(exc.errors())}, status_code=422)

    app.include_router(router)
    app.mount("/static", StaticFiles(directory=STATIC_DIR), name="static")
    install_docs(app)
    app.add_middleware(SecurityMiddleware, settings=settings)
    if settings.cors_origins:
        from fastapi.middleware.cors import CORSMiddleware

        app.add_middleware(  # outermost: answers preflights, adds headers to every answer (also 401/403)
            CORSMiddleware,
            allow_origins=list(settings.cors_origins),
            allow_methods=["GET", "POST", "PUT", "PATCH", "DELETE"],
            allow_headers=["Authorization", "Content-Type"],
        )
    default_openapi = app.openapi

    def openapi() -> dict[str, Any]:
        if app.openapi_schema is None:
            schema = document_error_bodies(default_openapi())
            app.openapi_schema = openapi_security(schema) if settings.token else schema
        return app.openapi_schema

    app.openapi = openapi  # type: ignore[method-assign]

    @app.get("/", include_in_schema=False)
    def index() -> FileResponse:
        return FileResponse(STATIC_DIR / "index.html", headers={"Cache-Control": "no-cache"})

    @app.get("/board", include_in_schema=False)
    @app.get("/board/{class_id}", include_in_schema=False)
    def board_page(class_id: str = "") -> FileResponse:
        """The class board (app/static/board.html): create a class, watch its seats."""
        return FileResponse(STATIC_DIR / "board.html", headers={"Cache-Control": "no-cache"})

    @app.get("/join/{code}", include_in_schema=False)
    def join_page(code: str) -> FileResponse:
        """A student's join page: takes a seat with the code, then opens the seat's session in the main page."""
        return FileResponse(STATIC_DIR / "join.html", headers={"Cache-Control": "no-cache"})

    return app
