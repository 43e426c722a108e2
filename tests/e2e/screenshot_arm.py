"""Take the README screenshot of the workbench with the arm: ``python -m tests.e2e.screenshot_arm
docs/workbench-arm.png 1600 1000``.

Scans the built-in L-block on the UR5 cell for a few views, plans, and saves the page with this tab's viewer
showing the arm at its joints, the translucent ghost at the planner's choice and the camera's path to it.
"""

from __future__ import annotations

import sys
import tempfile
from pathlib import Path

import httpx

from app.settings import AppSettings
from tests.e2e.conftest import CHROMIUM_ARGS, chromium_path, free_port, running_server, save_screenshot


def main(out: str = "docs/workbench-arm.png", width: int = 1600, height: int = 1000, steps: int = 2) -> None:
    from playwright.sync_api import expect, sync_playwright

    with tempfile.TemporaryDirectory() as tmp:
        settings = AppSettings(port=free_port(), viser_port=0, data_dir=Path(tmp))
        with running_server(settings) as server, sync_playwright() as p:
            api = httpx.Client(base_url=server.url, timeout=300)
            sid = api.post("/api/sessions", json={"model": "l-block"}).json()["id"]
            api.post(f"/api/sessions/{sid}/capture")
            api.post(f"/api/sessions/{sid}/step", json={"count": steps})
            api.post(f"/api/sessions/{sid}/plan")
            browser = p.chromium.launch(executable_path=chromium_path(), args=CHROMIUM_ARGS)
            page = browser.new_page(viewport={"width": width, "height": height}, device_scale_factor=1)
            page.goto(f"{server.url}/?session={sid}")
            expect(page.locator("#state")).to_have_text("planned", timeout=60_000)
            expect(page.locator("#arm")).to_contain_text("arm:", timeout=60_000)
            viewer = page.evaluate("S.viewer")
            for _ in range(300):
                if "/robot/ghost" in api.get(f"/api/scene/{viewer}").json()["nodes"]:
                    break
                page.wait_for_timeout(200)
            api.post(
                f"/api/scene/{viewer}/camera", json={"position": [0.3, -0.95, 0.62], "look_at": [-0.22, 0.02, 0.17]}
            )
            save_screenshot(page, out, 12000)  # SwiftShader: the scene loads and renders
            browser.close()
    print(f"saved {out}")


if __name__ == "__main__":
    args = sys.argv[1:]
    main(args[0] if args else "docs/workbench-arm.png", *(int(a) for a in args[1:3]))
