"""Fixtures of the browser tests: a live workbench (uvicorn + viser on free ports, in this process) and a
headless Debian Chromium page. The helpers are plain functions so ``tests/e2e/screenshot.py`` can use them."""

from __future__ import annotations

import shutil
import time
from collections.abc import Callable, Iterator
from pathlib import Path
from typing import Any

import pytest

from app.settings import AppSettings
from tests.helpers import free_port, with_small_costs
from tests.servers import LiveServer, running_server

CHROMIUM_ARGS = [
    "--headless=new",
    "--no-sandbox",
    "--use-angle=swiftshader",
    "--enable-unsafe-swiftshader",
    "--disable-background-networking",
    "--disable-component-update",
    "--no-first-run",
    "--disable-sync",
    "--disable-gpu-compositing",  # the page composited in software: SwiftShader's GPU process 51 -> 34 CPU-s over
]  # the browser tests (the renderers and the browser the same), WebGL (the 3D view) still on SwiftShader


HOLD_VIEWER_FRAMES = """
(() => {
  if (window === window.top && !window.__nbvHoldTop) return;  // the 3D viewer's iframe (or a page that asks)
  if (window.__nbvDraw) return;  // held already (a page's script and its context's both ran)
  const raf = window.requestAnimationFrame.bind(window);
  const caf = window.cancelAnimationFrame.bind(window);
  const held = new Map();
  let next = 1e9, live = false, timer = null, drawn = 0;
  const waiters = [];
  const flush = () => {  // the frames asked for since the last one, run in one animation frame
    timer = null;
    const cbs = [...held.values()];
    held.clear();
    raf((t) => {
      cbs.forEach((cb) => cb(t));
      drawn += 1;
      waiters.splice(0).forEach((check) => check());
    });
  };
  window.__nbvFrames = (n) => new Promise((done) => {  // true once the page has drawn n more frames (false: 60 s)
    const goal = drawn + n;
    const check = () => {
      if (drawn >= goal) return done(true);
      waiters.push(check);
      if (live && timer === null) timer = setTimeout(flush, FRAME_MS);
    };
    check();
    setTimeout(() => done(false), 60000);
  });
  window.requestAnimationFrame = (cb) => {
    held.set(++next, cb);
    if (live && timer === null) timer = setTimeout(flush, FRAME_MS);
    return next;
  };
  window.cancelAnimationFrame = (id) => (held.delete(id) ? undefined : caf(id));
  window.__nbvDraw = (on) => {
    live = on;
    if (timer !== null) clearTimeout(timer);
    timer = null;
    if (on) flush();
  };
})();
""".replace("FRAME_MS", "500")
"""The browser tests hold the viewer's render loop (``requestAnimationFrame`` in its iframe): SwiftShader spends
0.3 core-s per frame of a session's scene, 0.6-0.7 of a core per open tab, on frames no test looks at. The scene
graph still follows every message (React commits without animation frames) and the tests read the websocket
frames, the page and the scene; a test that looks at pixels or picks in the 3D view calls :func:`draw_viewer`, and
the viewer then draws a frame every 500 ms at most (SwiftShader drew as many as two cores allowed: the timeline
test's two drawing views took 22 of the browser tests' 34 GPU-process CPU-seconds, 17 at one frame a second; most
of the rest is the first frame, its shaders compiled)."""


def draw_viewer(page: Any, on: bool = True) -> None:
    """Let the viewer of ``page`` draw frames again (or hold them, ``on=False``); drawing, return once it has drawn
    :data:`DRAWN_FRAMES` frames (SwiftShader compiles the scene's shaders for its first: 10-15 s on a busy machine,
    longer than a PNG's 15 s budget on the server)."""
    for frame in page.frames:
        if frame is not page.main_frame:
            frame.evaluate("(on) => window.__nbvDraw && window.__nbvDraw(on)", on)
            if on:
                frame.evaluate(f"() => window.__nbvFrames && window.__nbvFrames({DRAWN_FRAMES})")


DRAWN_FRAMES = 3
"""Frames a page has run when :func:`draw_viewer` and :func:`draw_page` return: the third's callback runs after
the first two have been drawn."""


HOLD_PAGE_FRAMES = "window.__nbvHoldTop = true;" + HOLD_VIEWER_FRAMES
"""The same for a page that is itself a viewer (the offline recording's player): add it with ``add_init_script``
before ``goto``, and let it draw with :func:`draw_page`."""


def draw_page(page: Any, on: bool = True) -> None:
    """Let a page held by :data:`HOLD_PAGE_FRAMES` draw frames again (or hold them, ``on=False``); drawing, return
    once it has drawn :data:`DRAWN_FRAMES` frames."""
    page.main_frame.evaluate("(on) => window.__nbvDraw && window.__nbvDraw(on)", on)
    if on:
        page.main_frame.evaluate(f"() => window.__nbvFrames && window.__nbvFrames({DRAWN_FRAMES})")


def shot_until(page: Any, take: Callable[[], bytes], done: Callable[[bytes], bool], timeout_ms: int = 30_000) -> bytes:
    """The first PNG of ``take()`` (a screenshot of ``page`` or of a part of it) that ``done`` accepts, or the last
    one taken by ``timeout_ms``: a drawing page's picture once SwiftShader has rendered what was asked (a fixed
    1.5 s sleep before one screenshot was the time of its slowest frames on a busy machine, and most waited it out
    for nothing)."""
    deadline = time.monotonic() + timeout_ms / 1000
    while True:
        png = take()
        if done(png) or time.monotonic() > deadline:
            return png
        page.wait_for_timeout(250)


def chromium_path() -> str:
    for name in ("chromium", "chromium-browser"):
        path = shutil.which(name)
        if path:
            return path
    raise RuntimeError("Debian's chromium is needed for the browser tests (make system-deps installs it)")


def save_screenshot(page: Any, out: str, settle_ms: int) -> None:
    """Save ``page`` as the PNG ``out`` (its folder made): the viewer's headless-only notification closed first (it
    lies under the page's layer bar), then ``settle_ms`` for SwiftShader to render the scene."""
    close = page.frame_locator("#viewer").locator("button.mantine-Notification-closeButton")
    if close.count():
        close.first.dispatch_event("click")
    page.wait_for_timeout(settle_ms)
    Path(out).parent.mkdir(parents=True, exist_ok=True)
    page.screenshot(path=out)


OUTPUT_DIR = Path(__file__).resolve().parents[2] / "test-output" / "e2e"


@pytest.fixture
def output_dir() -> Path:
    """Where the browser tests leave their screenshots (``test-output/e2e``; ``make clean`` removes it)."""
    OUTPUT_DIR.mkdir(parents=True, exist_ok=True)
    return OUTPUT_DIR


@pytest.fixture
def live_server(tmp_path: Path) -> Iterator[LiveServer]:
    settings = AppSettings(port=free_port(), viser_port=0, data_dir=tmp_path / "data", models_dir=tmp_path)
    with running_server(with_small_costs(settings)) as server:
        yield server


@pytest.fixture(scope="session")
def chromium() -> Iterator[Any]:
    """One headless Chromium per test process (its tests each get a fresh context: separate storage, cookies and
    pages), started when the first browser test of the process asks for it. A launch costs the driver, the
    browser and its GPU process about 2 CPU-seconds; eleven of them were a noticeable share of the suite."""
    from playwright.sync_api import sync_playwright

    with sync_playwright() as p:
        browser = p.chromium.launch(executable_path=chromium_path(), args=CHROMIUM_ARGS)
        try:
            yield browser
        finally:
            browser.close()


@pytest.fixture
def browser_context(chromium: Any) -> Iterator:
    """A browser context (tabs share it, like one browser window) at the smallest supported size, 1024x700."""
    context = chromium.new_context(viewport={"width": 1024, "height": 700}, device_scale_factor=1)
    context.add_init_script(HOLD_VIEWER_FRAMES)
    try:
        yield context
    finally:
        context.close()
