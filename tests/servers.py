"""A real workbench server on 127.0.0.1: uvicorn in a thread of the test process (:func:`running_server`), or an
``nbv serve`` process of its own (:func:`serve_process`) for the tests that signal or kill it."""

from __future__ import annotations

import subprocess
import sys
import threading
import time
from collections.abc import Iterator
from contextlib import contextmanager
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import httpx
import uvicorn

from app.main import create_app
from app.settings import AppSettings
from tests.helpers import free_port, small_costs_toml

REPO = Path(__file__).resolve().parents[1]


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


@contextmanager
def serve_process(
    data_dir: Path, models_dir: Path, log: Path, timeout: float = 60.0
) -> Iterator[tuple[subprocess.Popen, httpx.Client]]:
    """An ``nbv serve`` process on a free port with the tests' small camera and scoring (a ``--config`` file beside
    ``data_dir``), its output appended to ``log``; yields it once ``/api/health`` answers, with a client of
    ``timeout`` seconds. Killed on exit if still running."""
    port = free_port()
    config = data_dir.parent / "serve.toml"  # tests/helpers.py with_small_costs, as the in-process servers
    config.write_text(small_costs_toml())
    cmd = [sys.executable, "-m", "nbv.cli", "serve", "--port", str(port), "--viser-port", "0", "--config", str(config)]
    cmd += ["--data-dir", str(data_dir), "--models-dir", str(models_dir), "--log-level", "warning"]
    with open(log, "ab") as out:
        proc = subprocess.Popen(cmd, cwd=REPO, stdout=out, stderr=subprocess.STDOUT)
    client = httpx.Client(base_url=f"http://127.0.0.1:{port}", timeout=timeout)
    try:
        deadline = time.time() + 90
        while True:
            try:
                if client.get("/api/health").status_code == 200:
                    break
            except httpx.TransportError:
                pass
            if proc.poll() is not None or time.time() > deadline:
                raise RuntimeError(f"nbv serve did not start: {log.read_text()[-2000:]}")
            time.sleep(0.1)
        yield proc, client
    finally:
        client.close()
        if proc.poll() is None:
            proc.kill()
        proc.wait(30)
