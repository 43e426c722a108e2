"""Take the docs' screenshot of Calibrate mode: ``python -m tests.e2e.screenshot_calibration
docs/calibration-view.png 1500 950``.

Opens Calibrate on a simulated cell with the 'poor' calibration model (3 plate angles x 6 views), approves all
poses but the last three through the page, previews one of those (the ghost arm and the camera's path to it) and
saves the page: the pose table with each capture's residual, the estimate with its uncertainty and its error
against the simulated truth, and the calibration's 3D view (plate, target, the pose cameras, the arm).
"""

from __future__ import annotations

import sys
import tempfile
from pathlib import Path

import httpx

from app.settings import AppSettings
from tests.e2e.conftest import CHROMIUM_ARGS, chromium_path, free_port, running_server, save_screenshot


def main(out: str = "docs/calibration-view.png", width: int = 1500, height: int = 950) -> None:
    from playwright.sync_api import expect, sync_playwright

    with tempfile.TemporaryDirectory() as tmp:
        settings = AppSettings(port=free_port(), viser_port=0, data_dir=Path(tmp))
        with running_server(settings) as server, sync_playwright() as p:
            api = httpx.Client(base_url=server.url, timeout=300)
            browser = p.chromium.launch(executable_path=chromium_path(), args=CHROMIUM_ARGS)
            page = browser.new_page(viewport={"width": width, "height": height}, device_scale_factor=1)
            page.goto(f"{server.url}/?calibrate=new")
            page.fill("#cal-angles", "0,120,-120")
            page.get_by_test_id("cal-start").click()
            rows = page.locator("#cal-poses tbody tr")
            expect(rows).to_have_count(18, timeout=60_000)
            for i in range(15):
                rows.nth(i).locator("button[data-act=approve]").click()
                expect(rows.nth(i)).not_to_have_attribute("data-status", "pending", timeout=60_000)
            rows.nth(16).locator("button[data-act=preview]").click()
            expect(rows.nth(16)).to_have_class("selected")
            viewer = page.evaluate("window.Calibrate.state.viewer")
            api.post(f"/api/scene/{viewer}/camera", json={"position": [0.55, -1.5, 1.1], "look_at": [-0.3, 0.0, 0.15]})
            save_screenshot(page, out, 12000)  # SwiftShader: the scene loads and renders
            browser.close()
    print(f"saved {out}")


if __name__ == "__main__":
    args = sys.argv[1:]
    main(args[0] if args else "docs/calibration-view.png", *(int(a) for a in args[1:3]))
