"""Take the README screenshot of debugging a fit: ``python -m tests.e2e.screenshot_fit docs/workbench-fit.png``
(optional: width height, default 1600 1000; ``--model bunny.obj`` from /work/shared/models, the default).

Scans the model for 3 views (the default config), plans, then in the page: the clusters layer on and the layers
that hide it off (through the layer bar, as a person would), the camera on the object, the Fit panel in view. Prints each ellipsoid's fill ratio (what docs/method.md's threshold is set
against).
"""

from __future__ import annotations

import sys
import tempfile
from pathlib import Path

import httpx

from app.settings import AppSettings
from tests.e2e.conftest import free_port, running_server, save_screenshot
from tests.e2e.pages import model_arg, scanned_page
from workbench.settings import default_models_dir

MODELS = default_models_dir()  # ../shared/models beside the clone
SHOWN = {
    "clusters": True,
    **dict.fromkeys(("occupied", "frontier", "unknown", "ellipsoids", "candidates", "cloud", "nbv", "views", "bbox",
                     "sectors"), False),
}  # fmt: skip
"""The layers of the screenshot (the rest as the page has them)."""


def main(out: str, width: int = 1600, height: int = 1000, model: str = "bunny.obj") -> None:
    from playwright.sync_api import expect, sync_playwright

    with tempfile.TemporaryDirectory() as tmp:
        settings = AppSettings(port=free_port(), viser_port=0, data_dir=Path(tmp), models_dir=MODELS)
        with running_server(settings) as server, sync_playwright() as p:
            api = httpx.Client(base_url=server.url, timeout=300)
            browser, page, viewer, _ = scanned_page(p, api, server.url, model, 2, width, height)
            for name, on in SHOWN.items():
                box = page.locator(f"#layers input[data-layer='{name}']")
                if box.is_checked() != on:
                    box.click()
                    expect(box).to_be_checked(checked=on)
            expect(page.locator("#fit tbody tr").first).to_be_visible(timeout=60_000)
            fit = api.get(f"/api/scene/{viewer}/fit").json()
            for r in fit["rows"]:
                flag = " (flagged)" if r["low_fill"] else ""
                print(f"{r['label']:>4} {r['kind']:9} voxels {r['voxels']:5d} fill {100 * r['fill']:5.1f} %{flag}")
            api.post(f"/api/scene/{viewer}/camera", json={"position": [0.2, -0.17, 0.16], "look_at": [0.0, 0.0, 0.06]})
            page.locator("#fit-box").scroll_into_view_if_needed()
            save_screenshot(page, out, 5000)  # SwiftShader: the scene loads and renders
            browser.close()
    print(f"saved {out}")


if __name__ == "__main__":
    name, args = model_arg(sys.argv[1:])
    main(args[0] if args else "docs/workbench-fit.png", *(int(a) for a in args[1:3]), model=name)
