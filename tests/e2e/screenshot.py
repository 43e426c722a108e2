"""Take the README screenshot of the workbench: ``python -m tests.e2e.screenshot docs/workbench.png``.

Scans the built-in L-block with the paper's default parameters for a few views,
plans, selects a candidate other than the planner's choice (so the inspector
shows its breakdown and projection), points the viewer at the object and saves
the page.
"""

from __future__ import annotations

import sys
import tempfile
import time
from pathlib import Path

import httpx

from app.settings import AppSettings
from tests.e2e.conftest import CHROMIUM_ARGS, chromium_path, free_port, running_server


def main(out: str = "docs/workbench.png", steps: int = 2) -> None:
    from playwright.sync_api import expect, sync_playwright

    with tempfile.TemporaryDirectory() as tmp:
        settings = AppSettings(port=free_port(), viser_port=0, data_dir=Path(tmp))
        with running_server(settings) as server, sync_playwright() as p:
            api = httpx.Client(base_url=server.url, timeout=300)
            browser = p.chromium.launch(executable_path=chromium_path(), args=CHROMIUM_ARGS)
            page = browser.new_page(viewport={"width": 1600, "height": 1000}, device_scale_factor=1)
            page.goto(server.url + "/")
            expect(page.locator("#health")).to_have_text("server ok", timeout=20_000)
            page.select_option("#model", "l-block")
            page.click("#create")
            expect(page.locator("#state")).to_have_text("new", timeout=20_000)
            sid = page.locator("#session-select").input_value()
            page.click("#capture")
            expect(page.locator("#state")).to_have_text("ready", timeout=60_000)
            api.post(f"/api/sessions/{sid}/step", json={"count": steps})
            page.click("#plan")
            expect(page.locator("#state")).to_have_text("planned", timeout=120_000)
            rows = page.locator("#candidates tbody tr")
            expect(rows.first).to_be_visible()
            rows.nth(2).click()
            expect(page.locator("#projection")).to_be_visible(timeout=20_000)
            deadline = time.time() + 60
            while not api.get("/api/scene/cameras").json() and time.time() < deadline:
                time.sleep(0.2)
            api.post("/api/scene/camera", json={"position": [0.8, -0.62, 0.6], "look_at": [0.0, 0.0, 0.06]})
            close = page.frame_locator("#viewer").locator("button.mantine-Notification-closeButton")
            if close.count():
                close.first.click()
            time.sleep(4.0)  # SwiftShader: let the scene render
            Path(out).parent.mkdir(parents=True, exist_ok=True)
            page.screenshot(path=out)
            browser.close()
    print(f"saved {out}")


if __name__ == "__main__":
    main(*sys.argv[1:2])
