"""Helpers shared by the app tests (import them as ``from apphelpers import ...``; fixtures are in conftest.py)."""

from __future__ import annotations

import socket
import threading
import time
from collections.abc import Iterator
from contextlib import contextmanager
from dataclasses import dataclass
from typing import Any

from fastapi.testclient import TestClient

from app.main import create_app
from app.settings import AppSettings

BASE_URL = "http://127.0.0.1"
"""The Host the API answers to when bound to loopback (app/security.py refuses others)."""

SMALL: dict[str, Any] = {
    "voxel": {"resolution": 0.02},
    "candidates": {"count": 60, "parallels": 4},
    "cluster": {"t_min": 2, "t_max": 6},
}
"""A coarse map and few candidates: a capture + plan takes well under a second."""

CUBE_OBJ = """v 0 0 0
v 1 0 0
v 1 1 0
v 0 1 0
v 0 0 1
v 1 0 1
v 1 1 1
v 0 1 1
f 1 3 2
f 1 4 3
f 5 6 7
f 5 7 8
f 1 2 6
f 1 6 5
f 2 3 7
f 2 7 6
f 3 4 8
f 3 8 7
f 4 1 5
f 4 5 8
"""


# ---------------------------------------------------------------------- live servers (real sockets, 127.0.0.1 only)


def free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


@dataclass
class Live:
    url: str
    app: Any

    @property
    def registry(self) -> Any:
        return self.app.state.registry


@contextmanager
def running_server(settings: AppSettings) -> Iterator[Live]:
    """uvicorn serving ``create_app(settings)`` on 127.0.0.1:settings.port in a thread."""
    import uvicorn

    app = create_app(settings)
    server = uvicorn.Server(uvicorn.Config(app, host="127.0.0.1", port=settings.port, log_level="warning"))
    thread = threading.Thread(target=server.run, daemon=True)
    thread.start()
    deadline = time.time() + 30
    while not server.started:
        if time.time() > deadline or not thread.is_alive():
            raise RuntimeError("uvicorn did not start")
        time.sleep(0.02)
    try:
        yield Live(f"http://127.0.0.1:{settings.port}", app)
    finally:
        server.should_exit = True
        thread.join(30)


def registry_of(client: TestClient) -> Any:
    return client.app.state.registry  # type: ignore[attr-defined]
