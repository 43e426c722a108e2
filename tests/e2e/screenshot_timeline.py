"""Take the README screenshots of looking back at a scan: ``python -m tests.e2e.screenshot_timeline
docs/workbench-timeline.png docs/recording.png`` (optional: width height, default 1600 1000; ``--model bunny.obj``
from /work/shared/models, the default).

Scans the model for 5 views (the default config) with a plan pending, then in the page: the timeline stepped back
to view 2 with the keys (the 3D view, the candidates, the charts' cursor at view 2). Then the session's recording,
unzipped and served by ``python -m http.server``, in a second page as it plays its third view.
"""

from __future__ import annotations

import contextlib
import io
import sys
import tempfile
import zipfile
from pathlib import Path

import httpx

from app.settings import AppSettings
from tests.e2e.conftest import free_port, running_server, save_screenshot
from tests.e2e.pages import goto_when_up, model_arg, scanned_page, served
from workbench.settings import default_models_dir

MODELS = default_models_dir()  # ../shared/models beside the clone


def main(out: str, player_out: str, width: int = 1600, height: int = 1000, model: str = "bunny.obj") -> None:
    from playwright.sync_api import expect, sync_playwright

    with tempfile.TemporaryDirectory() as tmp:
        settings = AppSettings(port=free_port(), viser_port=0, data_dir=Path(tmp), models_dir=MODELS)
        with running_server(settings) as server, sync_playwright() as p:
            api = httpx.Client(base_url=server.url, timeout=300)
            browser, page, viewer, sid = scanned_page(p, api, server.url, model, 4, width, height)
            page.locator("body").click(position={"x": 5, "y": 5})
            for _ in range(4):
                page.keyboard.press("ArrowLeft")
            expect(page.get_by_test_id("timeline-label")).to_have_text("view 2 of 5", timeout=120_000)
            api.post(f"/api/scene/{viewer}/camera", json={"position": [0.75, -0.65, 0.6], "look_at": [0.0, 0.0, 0.06]})
            save_screenshot(page, out, 5000)  # SwiftShader: the scene loads and renders
            print(f"saved {out}")

            zipfile.ZipFile(io.BytesIO(api.get(f"/api/sessions/{sid}/recording").content)).extractall(tmp)
            folder = Path(tmp) / f"nbv-{sid}-recording"  # the zip's one top-level folder
            with served(folder) as base:
                player = browser.new_page(viewport={"width": width, "height": height}, device_scale_factor=1)
                goto_when_up(player, f"{base}/index.html")
                now = player.locator("#nbv-now")
                expect(now).to_contain_text("of 5", timeout=120_000)
                close = player.locator("button.mantine-Notification-closeButton")
                if close.count():  # the headless-only "software WebGL" note, over the steps' panel
                    with contextlib.suppress(Exception):
                        close.first.dispatch_event("click", timeout=2000)
                for _ in range(600):  # it plays, 2 s a view: from the third on (SwiftShader may take its time)
                    if now.text_content() in ("view 3 of 5", "view 4 of 5"):
                        break
                    player.wait_for_timeout(200)
                Path(player_out).parent.mkdir(parents=True, exist_ok=True)
                player.screenshot(path=player_out)
                print(f"saved {player_out} ({now.text_content()})")
            browser.close()


if __name__ == "__main__":
    name, args = model_arg(sys.argv[1:])
    outs = [a for a in args if a.endswith(".png")]
    sizes = [int(a) for a in args if not a.endswith(".png")]
    outs += ["docs/workbench-timeline.png", "docs/recording.png"][len(outs) :]
    main(outs[0], outs[1], *sizes[:2], model=name)
