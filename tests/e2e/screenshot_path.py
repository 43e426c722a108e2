"""Take the docs screenshot of the path layer: ``python -m tests.e2e.screenshot_path docs/workbench-path.png 1600
1000``.

Scans the built-in L-block on the UR5 cell for two views, plans, and saves this tab's 3D view (from beside the way the
camera goes) showing the camera frustums along the move to the planner's choice (the plate's turn, then the arm's
trajectory) beside the views taken, the next view and the ghost arm.
"""

from __future__ import annotations

import sys
import tempfile
from pathlib import Path

import httpx
import numpy as np

from app.settings import AppSettings
from tests.e2e.conftest import free_port, running_server, save_screenshot
from tests.e2e.pages import scanned_page

HIDDEN = ("unknown", "candidates", "sectors", "ellipsoids")
"""Layers the screenshot hides (the path among the views, the next view, the map's occupied and frontier voxels)."""


def main(
    out: str = "docs/workbench-path.png",
    width: int = 1600,
    height: int = 1000,
    steps: int = 1,
    viewer_only: bool = True,
) -> None:
    from playwright.sync_api import sync_playwright

    with tempfile.TemporaryDirectory() as tmp:
        settings = AppSettings(port=free_port(), viser_port=0, data_dir=Path(tmp))
        with running_server(settings) as server, sync_playwright() as p:
            api = httpx.Client(base_url=server.url, timeout=300)
            browser, page, viewer, sid = scanned_page(p, api, server.url, "l-block", steps, width, height)
            for _ in range(300):
                if "/path/frustums" in api.get(f"/api/scene/{viewer}").json()["nodes"]:
                    break
                page.wait_for_timeout(200)
            for name in HIDDEN:  # through the layer bar, as a person would
                page.locator(f"#layers input[data-layer='{name}']").uncheck()
            path = api.get(f"/api/sessions/{sid}/plan/path").json()
            print(f"path: {len(path['frames'])} frames at {path['rate_hz']} Hz over {path['duration']:.2f} s")
            ends = np.array([path["start"]["position"], path["end"]["position"]])
            look_at = (ends.mean(axis=0) + np.array([0.0, 0.0, 0.1])) / 2  # between the way and the object
            away = np.array([look_at[0], look_at[1], 0.0])
            away = away / max(float(np.linalg.norm(away)), 1e-9)
            eye = look_at + 0.9 * away + np.array([0.0, 0.0, 0.6]) + 0.5 * np.cross([0.0, 0.0, 1.0], away)
            api.post(f"/api/scene/{viewer}/camera", json={"position": eye.tolist(), "look_at": look_at.tolist()})
            save_screenshot(page, out, 12000)  # SwiftShader: the scene loads and renders
            if viewer_only:
                page.locator("#viewer").screenshot(path=out)
            browser.close()
    print(f"saved {out}")


if __name__ == "__main__":
    args = sys.argv[1:]
    main(args[0] if args else "docs/workbench-path.png", *(int(a) for a in args[1:3]))
