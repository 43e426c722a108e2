"""Looking back at a scan in Chromium (live server, the session's worker, real viser): the timeline scrubs a 3-view
session to view 2 (the viewer's nodes are those the live session drew at view 2: plan id, best index, voxel
counts) and back to now, the page's PNG of the 3D view, the picker's label pushed live; and the session's
recording, unzipped and served by ``python -m http.server``, plays in the browser with no workbench server up to
its last view (and opens from file:// too)."""

from __future__ import annotations

import io
import re
import zipfile
from pathlib import Path
from typing import Any

import httpx
import numpy as np
import pytest
from PIL import Image
from playwright.sync_api import BrowserContext, expect

from tests.e2e.conftest import HOLD_PAGE_FRAMES, draw_page, draw_viewer, shot_until
from tests.e2e.pages import goto_when_up, served
from tests.e2e.test_workbench_browser import Tab, _state
from tests.helpers import SMALL
from tests.servers import LiveServer
from tests.viewer_buffers import decode_frame_arrays

pytestmark = pytest.mark.e2e  # tests/conftest.py: the long groups are handed out first

VIEWS = 3
"""Views of the scanned session: view 2 is in the past with a view after it, the recording plays more than two."""


def _scan(api: httpx.Client, views: int) -> tuple[str, dict[int, dict[str, Any]]]:
    """A session of ``views`` views (the planner's choice each time) and a plan pending after the last; per view,
    the live session's status right after its plan."""
    sid = api.post("/api/sessions", json={"model": "l-block", "config": SMALL}).json()["id"]
    api.post(f"/api/sessions/{sid}/capture").raise_for_status()
    live = {}
    for view in range(1, views + 1):
        plan = api.post(f"/api/sessions/{sid}/plan").json()
        live[view] = api.get(f"/api/sessions/{sid}").json()
        if view < views:
            body = {"plan_id": plan["plan_id"], "index": plan["best"]["index"]}
            api.post(f"/api/sessions/{sid}/approve", json=body).raise_for_status()
    return sid, live


def _last_clouds(frames: list[bytes]) -> dict[str, int]:
    """Per /map/<kind> point cloud, how many points it had when last sent in ``frames``."""
    out = {}
    for data in frames:
        for m in decode_frame_arrays(data):
            name = m.get("name", "")
            if name.startswith("/map/") and m.get("type") == "PointCloudMessage":
                out[name.split("/")[2]] = len(np.asarray(m["props"]["points"])) // 3
    return out


def _non_white(png: bytes) -> float:
    rgb = np.asarray(Image.open(io.BytesIO(png)).convert("RGB")).astype(int)
    return float(np.mean(np.abs(rgb - 255).sum(axis=2) > 30))


def test_scrub_the_timeline_and_play_the_recording_offline(
    live_server: LiveServer, browser_context: BrowserContext, tmp_path: Path
) -> None:
    api = httpx.Client(base_url=live_server.url, timeout=120)
    sid, live = _scan(api, VIEWS)
    tab = Tab(browser_context, f"{live_server.url}/?session={sid}")
    page = tab.page
    _state(tab, "planned")
    page.wait_for_function("() => Boolean(S.viewer)", timeout=60_000)
    viewer = page.evaluate("S.viewer")
    tab.wait(lambda: api.get(f"/api/scene/{viewer}").json()["connected"], 60_000)
    label = page.get_by_test_id("timeline-label")
    expect(label).to_have_text(f"now · {VIEWS} views")
    now_nodes = set(api.get(f"/api/scene/{viewer}").json()["nodes"])
    assert f"/views/{VIEWS}/frustum" in now_nodes

    # back to view 2 with the keys (the slider's right end is now, the next key the last view)
    mark = len(tab.frames)
    page.locator("body").click(position={"x": 5, "y": 5})
    for _ in range(VIEWS - 1):
        page.keyboard.press("ArrowLeft")
    expect(label).to_have_text(f"view 2 of {VIEWS}", timeout=60_000)
    at2 = live[2]
    tab.wait(lambda: (api.get(f"/api/scene/{viewer}").json()["timeline"] or {}).get("view") == 2, 60_000)
    info = api.get(f"/api/scene/{viewer}").json()
    step = info["timeline"]
    assert step["plan_id"] == at2["pending_plan"]["plan_id"]
    assert step["best"]["index"] == at2["pending_plan"]["best"]["index"]
    assert step["voxels"] == at2["voxels"]
    nodes = set(info["nodes"])
    assert {"/views/1/frustum", "/views/2/frustum", "/nbv", "/candidates"} <= nodes and "/views/3/frustum" not in nodes
    tab.wait(lambda: _last_clouds(tab.frames[mark:]).get("occupied") == at2["voxels"]["occupied"])
    clouds = _last_clouds(tab.frames[mark:])
    assert {k: clouds[k] for k in ("occupied", "frontier", "unknown")} == {
        k: at2["voxels"][k] for k in ("occupied", "frontier", "unknown")
    }
    expect(page.locator("#plan-id")).to_contain_text(at2["pending_plan"]["plan_id"])
    expect(page.locator("#iteration")).to_have_text("2")
    expect(page.locator("#approve")).to_be_disabled()
    expect(page.locator("#chart-coverage line.cursor")).to_have_attribute("data-x", "2")
    assert page.locator("#candidates tbody tr").count() > 0
    assert api.get(f"/api/sessions/{sid}").json() == live[VIEWS]  # the live session did not move

    # a PNG of the 3D view as the tab shows it (view 2): the browser renders it, so its viewer draws for it
    draw_viewer(page)
    with page.expect_download(timeout=60_000) as download:
        page.get_by_test_id("snapshot").click()
    png = Path(download.value.path()).read_bytes()
    assert png[:8] == b"\x89PNG\r\n\x1a\n" and download.value.suggested_filename == f"{sid}-view2.png"
    assert _non_white(png) > 0.01  # the scene, not a blank canvas
    draw_viewer(page, False)

    # leave the timeline: the session now, every panel live again
    page.get_by_test_id("timeline-now").click()
    expect(label).to_have_text(f"now · {VIEWS} views")
    tab.wait(lambda: api.get(f"/api/scene/{viewer}").json()["timeline"] is None)
    assert f"/views/{VIEWS}/frustum" in api.get(f"/api/scene/{viewer}").json()["nodes"]
    expect(page.locator("#plan-id")).to_have_text(f"plan {live[VIEWS]['pending_plan']['plan_id']}")
    expect(page.locator("#iteration")).to_have_text(str(VIEWS))
    expect(page.locator("#approve")).to_be_enabled()

    recording = api.get(f"/api/sessions/{sid}/recording?step_seconds=0.5")  # of the VIEWS views, 0.5 s each
    assert recording.status_code == 200

    # the picker's label follows the session (it was listed as "planned · VIEWS views"): one more view, pushed
    option = page.locator(f"#session-select option[value='{sid}']")
    expect(option).to_contain_text(f"planned · {VIEWS} views")
    pending = live[VIEWS]["pending_plan"]
    api.post(f"/api/sessions/{sid}/approve", json={"plan_id": pending["plan_id"], "index": pending["best"]["index"]})
    expect(option).to_have_text(re.compile(rf"· (ready|done) · {VIEWS + 1} views$"), timeout=60_000)

    page.close()  # its viewer renders all the time: SwiftShader's cores go to the player from here

    # the recording of the VIEWS views, played with no workbench server
    zipfile.ZipFile(io.BytesIO(recording.content)).extractall(tmp_path)
    folder = tmp_path / f"nbv-{sid}-recording"  # the zip's one top-level folder
    with served(folder) as base:
        player = browser_context.new_page()
        player.add_init_script(HOLD_PAGE_FRAMES)  # the player is a viewer itself: it draws for the last check only
        logs: list[str] = []
        player.on("console", lambda m: logs.append(m.text))
        hosts: set[str] = set()
        player.on("request", lambda req: hosts.add(req.url.split("/")[2]))
        goto_when_up(player, f"{base}/index.html")
        time_box = player.locator(".mantine-NumberInput-input")
        expect(time_box).to_be_visible(timeout=60_000)
        assert any("Embedded data loaded" in line for line in logs)  # the scene decoded
        steps = player.get_by_test_id("recording-steps")
        expect(steps.locator("#nbv-now")).to_contain_text(f"of {VIEWS}", timeout=30_000)
        # it plays by itself, 0.5 s a view, up to the last, and loops: the views the panel named since it loaded
        # (a slow machine's timer may jump past some views, but the loop brings it back to view 1)
        player.wait_for_function(
            f"() => window.NBV_SHOWN.includes({VIEWS}) && new Set(window.NBV_SHOWN).size >= 2",
            polling=100,
            timeout=60_000,
        )  # polled on a timer: the page's animation frames are held
        shown = player.evaluate("window.NBV_SHOWN")
        assert set(shown) <= set(range(1, VIEWS + 1)), shown
        expect(steps.locator("#nbv-now")).to_have_text(re.compile(rf"^view [1-{VIEWS}] of {VIEWS}$"))
        assert steps.locator("tr").count() == VIEWS
        # paused (space, the player's own key) before it draws: each loop resets viser's environment to its
        # default image-based light until the recording's own light arrives again, and a software renderer
        # prefilters that image anew (seconds of CPU a loop); a paused player shows its scene as it stands
        player.keyboard.press("Space")
        paused_at = time_box.input_value()
        player.wait_for_timeout(600)  # a playing player moves its time box on within a tick (120 a second)
        assert time_box.input_value() == paused_at
        draw_page(player)  # the player draws from here: viser's scene tree and the canvas need its frames
        player.get_by_label("Show scene tree").click()  # viser's own scene tree: the nodes its player decoded
        player.get_by_text("/views", exact=True).click()
        expect(player.get_by_text(f"/{VIEWS}", exact=True)).to_be_visible(timeout=30_000)
        assert player.get_by_text(f"/{VIEWS + 1}", exact=True).count() == 0
        canvas = shot_until(player, player.locator("canvas").first.screenshot, lambda png: _non_white(png) > 0.01)
        assert _non_white(canvas) > 0.01  # SwiftShader has drawn the scene
        assert hosts == {base.split("/")[2]}  # nothing from the workbench, nothing from the internet

        player.close()
        opened = browser_context.new_page()  # and from the folder itself, no server at all
        opened.add_init_script(HOLD_PAGE_FRAMES)
        file_logs: list[str] = []
        opened.on("console", lambda m: file_logs.append(m.text))
        opened.goto((folder / "index.html").as_uri())
        expect(opened.get_by_test_id("recording-steps").locator("#nbv-now")).to_contain_text(
            f"of {VIEWS}", timeout=60_000
        )
        assert any("Embedded data loaded" in line for line in file_logs)
