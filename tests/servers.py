"""A real uvicorn serving the workbench on 127.0.0.1 in a thread of the test process."""

from __future__ import annotations

import threading
import time
from collections.abc import Iterator
from contextlib import contextmanager
from dataclasses import dataclass
from typing import Any

import uvicorn

from app.main import create_app
from app.settings import AppSettings


@dataclass
class LiveServer:
    url: str
    app: Any

    @property
    def registry(self) -> Any:
        return self.app.state.registry


@contextmanager
def running_server(settings: AppSettings) -> Iterator[LiveServer]:
    """uvicorn serving ``create_app(settings)`` on 127.0.0.1:settings.port; stopped on exit."""
    app = create_app(settings)
    # keep-alive longer than any gap between two requests: a client reusing a connection the server is closing
    # gets "connection reset" (the 5 s default loses that race on a busy machine)
    config = uvicorn.Config(app, host="127.0.0.1", port=settings.port, log_level="warning", timeout_keep_alive=120)
    server = uvicorn.Server(config)
    thread = threading.Thread(target=server.run, daemon=True)
    thread.start()
    deadline = time.time() + 30
    while not server.started:
        if time.time() > deadline or not thread.is_alive():
            raise RuntimeError("uvicorn did not start")
        time.sleep(0.02)
    try:
        yield LiveServer(f"http://127.0.0.1:{settings.port}", app)
    finally:
        server.should_exit = True
        thread.join(30)
