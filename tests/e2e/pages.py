"""Helpers of the browser tests and the screenshot scripts: a session's page opened with its viewer connected, and a
folder served by ``python -m http.server`` (a recording played with no workbench server)."""

from __future__ import annotations

import contextlib
import subprocess
import sys
from collections.abc import Iterator
from pathlib import Path
from typing import Any

from tests.helpers import free_port


def open_session(browser: Any, url: str, sid: str, width: int, height: int, api: Any) -> tuple[Any, str]:
    """A new page of ``browser`` on session ``sid`` of the server at ``url``, once it shows ``planned`` and its
    viewer is connected: (page, viewer id)."""
    from playwright.sync_api import expect

    page = browser.new_page(viewport={"width": width, "height": height}, device_scale_factor=1)
    page.goto(f"{url}/?session={sid}")
    expect(page.locator("#state")).to_have_text("planned", timeout=120_000)
    page.wait_for_function("() => Boolean(S.viewer)", timeout=60_000)
    viewer = page.evaluate("S.viewer")
    for _ in range(300):
        if api.get(f"/api/scene/{viewer}").json()["connected"]:
            break
        page.wait_for_timeout(200)
    return page, viewer


def scanned_page(
    p: Any, api: Any, url: str, model: str, steps: int, width: int, height: int
) -> tuple[Any, Any, str, str]:
    """A session of ``model`` (the default config) scanned for 1 + ``steps`` views with a plan pending, and a new
    headless Chromium (of playwright ``p``) showing it: (browser, page, viewer id, session id)."""
    from tests.e2e.conftest import CHROMIUM_ARGS, chromium_path

    sid = api.post("/api/sessions", json={"model": model}).json()["id"]
    api.post(f"/api/sessions/{sid}/capture")
    api.post(f"/api/sessions/{sid}/step", json={"count": steps})
    api.post(f"/api/sessions/{sid}/plan")
    browser = p.chromium.launch(executable_path=chromium_path(), args=CHROMIUM_ARGS)
    page, viewer = open_session(browser, url, sid, width, height, api)
    return browser, page, viewer, sid


@contextlib.contextmanager
def served(folder: Path) -> Iterator[str]:
    """``folder`` served by ``python -m http.server`` on a free loopback port: its base URL."""
    port = free_port()
    static = subprocess.Popen(
        [sys.executable, "-m", "http.server", str(port), "--bind", "127.0.0.1", "--directory", str(folder)],
        stdout=subprocess.DEVNULL,
        stderr=subprocess.DEVNULL,
    )
    try:
        yield f"http://127.0.0.1:{port}"
    finally:
        static.kill()
        static.wait(5)


def goto_when_up(page: Any, url: str) -> None:
    """Open ``url`` in ``page`` once its server answers (a static server just started)."""
    for _ in range(50):
        try:
            page.goto(url)
            return
        except Exception:
            page.wait_for_timeout(100)
    page.goto(url)


def model_arg(args: list[str], default: str = "bunny.obj") -> tuple[str, list[str]]:
    """A screenshot script's ``--model NAME`` (a file in the models directory or a built-in) and the other
    arguments."""
    if "--model" not in args:
        return default, args
    i = args.index("--model")
    return args[i + 1], args[:i] + args[i + 2 :]
