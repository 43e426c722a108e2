"""Helpers shared by the app tests (import them as ``from apphelpers import ...``; fixtures are in conftest.py)."""

from __future__ import annotations

from typing import Any

from fastapi.testclient import TestClient

from tests.helpers import SMALL, free_port
from tests.servers import LiveServer as Live
from tests.servers import running_server

__all__ = ["BASE_URL", "CUBE_OBJ", "SMALL", "Live", "free_port", "registry_of", "running_server"]

BASE_URL = "http://127.0.0.1"
"""The Host the API answers to when bound to loopback (app/security.py refuses others)."""

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


def registry_of(client: TestClient) -> Any:
    return client.app.state.registry  # type: ignore[attr-defined]
