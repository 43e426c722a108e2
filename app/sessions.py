"""The registry of live sessions. Each Workbench has its own lock, so sessions run side by side;
the registry's lock guards only the dict of sessions."""

from __future__ import annotations

import secrets
import threading
from collections.abc import Callable
from typing import Any

from app.errors import NotFoundError, UnprocessableError
from app.models import load_model
from app.settings import AppSettings
from app.workbench import Workbench
from planner import PlannerConfig

SURFACE_SAMPLES = 10_000
"""Points sampled on the ground-truth mesh to measure coverage (simulation only)."""


class SessionRegistry:
    """Creates, finds and deletes sessions. ``on_create`` / ``on_delete`` hooks let the scene follow."""

    def __init__(self, settings: AppSettings) -> None:
        self.settings = settings
        self._lock = threading.Lock()
        self._sessions: dict[str, Workbench] = {}
        self.on_create: list[Callable[[Workbench], None]] = []
        self.on_delete: list[Callable[[Workbench], None]] = []

    def planner_config(self, overrides: dict[str, Any] | None, seed: int) -> PlannerConfig:
        """The default planner config with ``overrides`` (any subset); the seed goes to ``cluster.seed``
        unless the overrides set it. UnprocessableError for unknown names or values out of range."""
        overrides = dict(overrides or {})
        cluster = overrides.get("cluster") or {}
        if isinstance(cluster, dict):
            overrides["cluster"] = {"seed": seed, **cluster}
        try:
            return self.settings.planner.replace(**overrides)
        except (ValueError, TypeError) as exc:
            raise UnprocessableError(f"config: {exc}") from None

    def create(self, model: str | None = None, config: dict[str, Any] | None = None, seed: int = 0) -> Workbench:
        """A new session on the simulated cell. 422 for a bad config, an unknown model or an unusable mesh."""
        import dataclasses

        from devices.mesh import sample_surface
        from devices.sim import make_sim_cell

        planner_config = self.planner_config(config, seed)
        name = model or self.settings.devices.model
        try:
            mesh = load_model(self.settings, name)
        except NotFoundError as exc:  # a bad parameter of this request, not an unknown resource
            raise UnprocessableError(exc.detail) from None
        devices = dataclasses.replace(self.settings.devices, model=name, seed=seed)
        try:
            cell = make_sim_cell(mesh, devices.camera, devices.cell, seed=seed)
            samples = sample_surface(mesh, SURFACE_SAMPLES, seed=seed)
        except ValueError as exc:
            raise UnprocessableError(f"model {name!r}: {exc}") from None
        with self._lock:
            session_id = secrets.token_hex(4)
            while session_id in self._sessions:
                session_id = secrets.token_hex(4)
            wb = Workbench(session_id, name, mesh, cell, planner_config, devices, seed, samples)
            self._sessions[session_id] = wb
        for hook in list(self.on_create):
            hook(wb)
        return wb

    def get(self, session_id: str) -> Workbench:
        with self._lock:
            wb = self._sessions.get(session_id)
        if wb is None:
            raise NotFoundError(f"session {session_id!r}: unknown")
        return wb

    def list(self) -> list[Workbench]:
        with self._lock:
            return list(self._sessions.values())

    def delete(self, session_id: str) -> None:
        with self._lock:
            wb = self._sessions.pop(session_id, None)
        if wb is None:
            raise NotFoundError(f"session {session_id!r}: unknown")
        wb.close()
        for hook in list(self.on_delete):
            hook(wb)

    def close(self) -> None:
        """Stop every session's auto mode (shutdown)."""
        for wb in self.list():
            wb.close(timeout=10.0)
