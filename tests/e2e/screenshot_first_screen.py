"""Take the getting-started screenshots of the first screen and the guided mode:
``python -m tests.e2e.screenshot_first_screen docs [--model NAME]``.

Saves ``first-screen.png`` (the page with no session, 1024x700: the cell and the default object in 3D),
``guided-mode.png`` (the demo scan after one click, the guide on, 1366x768) and ``workbench-1024.png`` (the page
at 1024x700 after the first approved view).
The demo uses the server's default object (``--model`` sets the server's models directory's first choice: the
shared bunny when ``../shared/models`` exists).
"""

from __future__ import annotations

import sys
import tempfile
from pathlib import Path

import httpx

from app.settings import AppSettings
from tests.e2e.conftest import CHROMIUM_ARGS, chromium_path, draw_viewer, free_port, running_server, save_screenshot


def main(out_dir: str = "docs") -> None:
    from playwright.sync_api import expect, sync_playwright

    out = Path(out_dir)
    with tempfile.TemporaryDirectory() as tmp:
        settings = AppSettings(port=free_port(), viser_port=0, data_dir=Path(tmp))
        with running_server(settings) as server, sync_playwright() as p:
            api = httpx.Client(base_url=server.url, timeout=300)
            browser = p.chromium.launch(executable_path=chromium_path(), args=CHROMIUM_ARGS)
            page = browser.new_page(viewport={"width": 1024, "height": 700}, device_scale_factor=1)
            page.goto(f"{server.url}/")
            expect(page.get_by_test_id("demo")).to_be_visible()
            page.wait_for_timeout(8000)  # the 3D view of the cell drawn (and viser's headless notice up, closed next)
            save_screenshot(page, str(out / "first-screen.png"), 1000)
            page.set_viewport_size({"width": 1366, "height": 768})
            page.get_by_test_id("demo").click()  # one click: a session, its first view and a plan
            expect(page.locator("#state")).to_have_text("planned", timeout=240_000)
            expect(page.get_by_test_id("guide")).to_be_visible()
            page.wait_for_function("() => Boolean(S.viewer)", timeout=60_000)
            viewer = page.evaluate("S.viewer")
            for _ in range(300):
                if api.get(f"/api/scene/{viewer}").json()["connected"]:
                    break
                page.wait_for_timeout(200)
            draw_viewer(page)
            save_screenshot(page, str(out / "guided-mode.png"), 4000)
            page.get_by_test_id("approve").click()  # two clicks: the first approved view
            expect(page.locator("#iteration")).to_have_text("2", timeout=240_000)
            expect(page.locator("#state")).to_have_text("ready", timeout=60_000)
            page.get_by_test_id("guided-toggle").uncheck()
            page.set_viewport_size({"width": 1024, "height": 700})
            save_screenshot(page, str(out / "workbench-1024.png"), 4000)
            browser.close()
    print(f"saved {out}/first-screen.png, guided-mode.png, workbench-1024.png")


if __name__ == "__main__":
    main(*sys.argv[1:2])
