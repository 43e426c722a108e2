"""Take the README screenshots of the workbench page:
``python -m tests.e2e.screenshot docs/workbench.png 1600 1000`` (and ``docs/workbench-1024.png 1024 700``);
``python -m tests.e2e.screenshot docs/workbench-surface.png 1600 1000 --surface``: the reconstructed surface layer
shown (the voxel and cloud layers hidden), after more views.

Scans the built-in L-block for a few views, plans, selects a candidate other than the planner's choice (so the
inspector shows its breakdown and projection), points this tab's viewer at the object and saves the page.
"""

from __future__ import annotations

import sys
import tempfile
from pathlib import Path

import httpx

from app.settings import AppSettings
from tests.e2e.conftest import CHROMIUM_ARGS, chromium_path, free_port, running_server, save_screenshot

SURFACE_LAYERS = {
    "surface": True,
    **dict.fromkeys(("occupied", "frontier", "unknown", "cloud", "ellipsoids", "candidates", "sectors"), False),
}
"""The layers of the surface screenshot (the rest as the page has them)."""


def main(
    out: str = "docs/workbench.png", width: int = 1600, height: int = 1000, steps: int = 2, surface: bool = False
) -> None:
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
            rows = page.locator("#candidates tbody tr")
            expect(rows.first).to_be_visible()
            rows.nth(2).click()
            expect(page.locator("#projection")).to_be_visible(timeout=20_000)
            viewer = page.evaluate("S.viewer")
            for _ in range(300):
                if api.get(f"/api/scene/{viewer}").json()["connected"]:
                    break
                page.wait_for_timeout(200)
            eye = [0.42, -0.33, 0.3] if surface else [0.8, -0.62, 0.6]
            api.post(f"/api/scene/{viewer}/camera", json={"position": eye, "look_at": [0.0, 0.0, 0.06]})
            if surface:
                for name, on in SURFACE_LAYERS.items():  # through the layer bar, as a person would
                    box = page.locator(f"#layers input[data-layer='{name}']")
                    if box.is_checked() != on:
                        box.click()
            save_screenshot(page, out, 5000)  # SwiftShader: the scene loads and renders
            browser.close()
    print(f"saved {out}")


if __name__ == "__main__":
    args = [a for a in sys.argv[1:] if a != "--surface"]
    with_surface = "--surface" in sys.argv[1:]
    main(args[0] if args else "docs/workbench.png", *(int(a) for a in args[1:3]), steps=5 if with_surface else 2,
         surface=with_surface)  # fmt: skip
