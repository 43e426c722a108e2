"""Take the class board's screenshot: ``python -m tests.e2e.screenshot_board docs/class-board.png 1400 900``.

A class of 8 guided seats on two objects; six seats scan a few views each (different counts), two of them are
then put to sleep (their cards keep their last picture), and the board is saved as the teacher sees it.
"""

from __future__ import annotations

import sys
import tempfile
from pathlib import Path

import httpx

from app.settings import AppSettings
from tests.e2e.conftest import CHROMIUM_ARGS, chromium_path, free_port, running_server
from tests.helpers import SMALL, with_small_costs


def main(out: str = "docs/class-board.png", width: int = 1400, height: int = 900) -> None:
    from playwright.sync_api import expect, sync_playwright

    with tempfile.TemporaryDirectory() as tmp:
        settings = with_small_costs(AppSettings(port=free_port(), viser_port=0, data_dir=Path(tmp)))
        with running_server(settings) as server, sync_playwright() as p:
            api = httpx.Client(base_url=server.url, timeout=300)
            config = {**SMALL, "voxel": {"resolution": 0.01}}
            made = api.post(
                "/api/classes", json={"seats": 8, "model": ["l-block", "mug"], "guided": True, "config": config}
            ).json()
            for seat, views in zip(made["seats"], [4, 3, 2, 3, 1, 2, 0, 0], strict=True):
                if views:
                    api.post("/api/classes/join", json={"code": made["code"]})
                    api.post(f"/api/sessions/{seat['session']}/capture").raise_for_status()
                if views > 1:
                    api.post(f"/api/sessions/{seat['session']}/step", json={"count": views - 1}).raise_for_status()
            browser = p.chromium.launch(executable_path=chromium_path(), args=CHROMIUM_ARGS)
            page = browser.new_page(viewport={"width": width, "height": height}, device_scale_factor=1)
            page.goto(f"{server.url}/board/{made['id']}")
            expect(page.locator("img.pic")).to_have_count(6, timeout=60_000)  # every picture drawn once
            for seat in made["seats"][4:6]:  # these two sleep now: their cards keep their last picture
                server.registry.sleep(seat["session"])
            api.post(f"/api/sessions/{made['seats'][1]['session']}/plan").raise_for_status()
            expect(page.get_by_test_id("seat-5-state")).to_have_text("asleep", timeout=30_000)
            page.wait_for_timeout(2500)
            Path(out).parent.mkdir(parents=True, exist_ok=True)
            page.screenshot(path=out)
            browser.close()
    print(f"saved {out}")


if __name__ == "__main__":
    args = sys.argv[1:]
    main(args[0] if args else "docs/class-board.png", *(int(a) for a in args[1:3]))
