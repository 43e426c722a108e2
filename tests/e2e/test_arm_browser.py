"""The arm in the workbench page (real Chromium, live server, the UR5 sim cell): the tab's viewer receives the arm
and the ghost of the planner's choice under /robot (decoded viser frames), the page says where the move goes
and why unreachable candidates are unreachable; the path layer draws the camera frustums along the move before
approval (re-drawn for another selection, gone once approved); Preview motion plays the move on the ghost (the real
arm stays), Approve executes it and the arm's joints animate in the view; the reach layer draws the hemisphere coloured by what
the arm reaches (the reachable colour in the view's pixels) with its legend."""

from __future__ import annotations

import io
from pathlib import Path

import httpx
import numpy as np
import pytest
from playwright.sync_api import BrowserContext, expect

from app.scene.reachlayer import REACH_CLASSES
from tests.e2e.conftest import draw_viewer, shot_until
from tests.e2e.test_workbench_browser import Tab, _state
from tests.helpers import SMALL
from tests.servers import LiveServer

pytestmark = pytest.mark.e2e  # tests/conftest.py: the long groups are handed out first

REASONS = ("no_ik", "joint_limit", "collision:", "no_path")
PATH_NODES = ("/path/frustums", "/path/edges", "/path/line")


def _path_drawn(tab: Tab, start: int) -> bool:
    """Whether the viewer received the path layer's nodes (frustums with one instance per frame) after frame
    ``start``."""
    names = {str(m.get("name")) for m in tab.messages(start) if "props" in m}
    return set(PATH_NODES) <= names


def _path_removed(tab: Tab, start: int) -> bool:
    """Whether the viewer was told to remove the path layer's nodes after frame ``start``."""
    gone = {str(m.get("name")) for m in tab.messages(start) if m.get("type") == "RemoveSceneNodeMessage"}
    return set(PATH_NODES) <= gone


def _frustum_count(tab: Tab, start: int) -> int:
    """Instances of the last /path/frustums the viewer received after frame ``start`` (its positions' bytes / 12)."""
    sent = [m for m in tab.messages(start) if m.get("name") == "/path/frustums" and "props" in m]
    return int(sent[-1]["props"]["batched_positions"]["nbytes"]) // 12 if sent else 0


def _updates(tab: Tab, prefix: str, start: int) -> int:
    """How many messages after frame ``start`` move or re-pose nodes under ``prefix`` (joint updates)."""
    return sum(
        1
        for m in tab.messages(start)
        if str(m.get("name", "")).startswith(prefix) and m.get("type", "").startswith(("SetPosition", "SetOrientation"))
    )


def _pixels_near(png: bytes, color: tuple[int, int, int]) -> int:
    """Pixels of ``png`` within 35 of ``color`` in every channel."""
    from PIL import Image

    rgb = np.asarray(Image.open(io.BytesIO(png)).convert("RGB"), dtype=np.int32)
    return int(np.sum(np.max(np.abs(rgb - np.array(color)), axis=2) <= 35))


def _path_pixels(png: bytes) -> int:
    """Pixels of ``png`` in the path layer's cyan-to-blue as SwiftShader renders its lines (lit lighter: about
    (110, 200, 220) for the line's (0, 205, 255)): blue and green high, red well under blue; the grey arm, the
    pale ghost and the plate are not."""
    from PIL import Image

    rgb = np.asarray(Image.open(io.BytesIO(png)).convert("RGB"), dtype=np.int32)
    r, g, b = rgb[..., 0], rgb[..., 1], rgb[..., 2]
    return int(np.sum((b >= 190) & (g >= 150) & (r <= 150) & (b - r >= 70)))


def _scene_shot(tab: Tab, out: Path) -> bytes:
    """The viewer's 3D view as a PNG (saved to ``out``) without the page's overlays (the layer bar and the legend,
    whose swatches have the layers' colours)."""
    hide = "(v) => ['legend', 'layers'].forEach((id) => { document.getElementById(id).style.visibility = v; })"
    tab.page.evaluate(hide, "hidden")
    try:
        return tab.page.locator("#viewer").screenshot(path=str(out))
    finally:
        tab.page.evaluate(hide, "")


def _reachable_pixels(png: bytes) -> int:
    """Pixels of ``png`` near the reach layer's reachable colour (no viridis stop of the candidates is near it)."""
    return _pixels_near(png, REACH_CLASSES["reachable"][1])


def test_arm_preview_and_approve(live_server: LiveServer, browser_context: BrowserContext, output_dir: Path) -> None:
    api = httpx.Client(base_url=live_server.url, timeout=120)
    sid = api.post("/api/sessions", json={"model": "l-block", "config": SMALL}).json()["id"]
    api.post(f"/api/sessions/{sid}/capture")
    best = api.post(f"/api/sessions/{sid}/plan").json()["best"]["index"]
    tab = Tab(browser_context, f"{live_server.url}/?session={sid}")
    _state(tab, "planned")

    # the viewer's frames carry the arm's and the ghost's link meshes
    def meshes() -> set[str]:
        return {str(m["name"]) for m in tab.messages() if m.get("type") in ("GlbMessage", "MeshMessage")}

    def links(root: str) -> int:
        return sum(n.startswith(root) for n in meshes())

    tab.wait(lambda: links("/robot/arm/") >= 7 and links("/robot/ghost/") >= 7, timeout_ms=60_000)
    tab.wait(lambda: any(m.get("name") == "/robot/path" for m in tab.messages()))
    arm = api.get(f"/api/sessions/{sid}/arm").json()
    q0 = arm["joints"]
    assert arm["target"]["index"] == best and arm["target"]["reachable"]

    # the path layer: a frustum per frame the move would take, drawn before approval; re-drawn for another view
    tab.wait(lambda: _path_drawn(tab, 0))
    path = api.get(f"/api/sessions/{sid}/plan/path").json()
    assert path["target"]["index"] == best and len(path["frames"]) >= 2
    assert _frustum_count(tab, 0) == len(path["frames"])
    other = next(
        c["index"] for c in api.get(f"/api/sessions/{sid}/candidates").json() if c["eligible"] and not c["best"]
    )
    mark = len(tab.frames)
    api.put(f"/api/sessions/{sid}/selection", json={"index": other}).raise_for_status()
    tab.wait(lambda: _path_drawn(tab, mark))  # sent again under the same names (viser replaces them)
    moved = api.get(f"/api/sessions/{sid}/plan/path").json()
    assert moved["target"]["index"] == other and moved["end"] != path["end"]
    assert _frustum_count(tab, mark) == len(moved["frames"])
    mark = len(tab.frames)
    api.put(f"/api/sessions/{sid}/selection", json={"index": best}).raise_for_status()
    tab.wait(lambda: _path_drawn(tab, mark))

    # the page: where the move goes; unreachable rows carry the cell's reason
    expect(tab.page.locator("#arm")).to_contain_text(f"arm: move to candidate {best} in", timeout=30_000)
    items = tab.page.evaluate("window.Panels.Table.items")
    unreachable = [c for c in items if not c["eligible"] and c["reason"].startswith("unreachable")]
    # (how many the plan finds unreachable depends on the cell and the planner's sectors; often a few)
    assert all(c["reason"].startswith("unreachable: ") for c in unreachable)
    assert all(c["reason"][len("unreachable: ") :].startswith(REASONS) for c in unreachable)
    assert {str(c["index"]) for c in unreachable} == set(arm["unreachable"])

    # Preview motion: the ghost's joints move, the arm's and the real joints do not
    mark = len(tab.frames)
    expect(tab.page.locator("#preview")).to_be_enabled()
    tab.page.click("#preview")
    tab.wait(lambda: _updates(tab, "/robot/ghost/", mark) > 20)
    assert _updates(tab, "/robot/arm/", mark) == 0
    np.testing.assert_allclose(api.get(f"/api/sessions/{sid}/arm").json()["joints"], q0)

    # Approve: the sim arm executes the move, the arm in the view animates to the new joints
    tab.page.wait_for_timeout(float(arm["target"]["duration"]) * 1000 + 500)  # the preview ends
    mark = len(tab.frames)
    tab.page.click("#approve")
    expect(tab.page.locator("#iteration")).to_have_text("2", timeout=60_000)
    tab.wait(lambda: _updates(tab, "/robot/arm/", mark) > 20)
    tab.wait(lambda: _path_removed(tab, mark))  # approved: no path is previewed any more
    viewer = tab.page.evaluate("S.viewer")
    assert not set(PATH_NODES) & set(api.get(f"/api/scene/{viewer}").json()["nodes"])
    q1 = api.get(f"/api/sessions/{sid}/arm").json()["joints"]
    np.testing.assert_allclose(q1, arm["target"]["joints"], atol=1e-6)
    assert not np.allclose(q1, q0)

    # the reach layer from the layer bar: the hemisphere coloured by what the arm reaches, drawn only when shown
    assert "/reach/points" not in api.get(f"/api/scene/{viewer}").json()["nodes"]
    shown = ("turntable", "reach")  # only the plate under the points: no other layer's colours in the picture
    api.put(f"/api/scene/{viewer}/layers", json={k: False for k in tab.page.evaluate("Object.keys(S.layers)")})
    draw_viewer(tab.page)
    blank = shot_until(  # SwiftShader: the hidden layers rendered away
        tab.page,
        lambda: _scene_shot(tab, output_dir / "arm-blank.png"),
        lambda png: _reachable_pixels(png) < 20 and _path_pixels(png) < 50,
    )
    before = _reachable_pixels(tab.page.locator("#viewer").screenshot())
    path_before = _path_pixels(blank)
    tab.page.locator("#layers input[data-layer='turntable']").check()
    tab.page.locator("#layers input[data-layer='reach']").check(timeout=60_000)
    tab.wait(lambda: "/reach/points" in api.get(f"/api/scene/{viewer}").json()["nodes"], timeout_ms=60_000)
    assert all(api.get(f"/api/scene/{viewer}").json()["layers"][k] for k in shown)
    legend = tab.page.get_by_test_id("reach-legend")
    expect(legend).to_be_visible()
    expect(legend.locator("[data-reach-class='reachable']")).to_contain_text("reachable (", timeout=30_000)
    shot = shot_until(tab.page, tab.page.locator("#viewer").screenshot, lambda png: _reachable_pixels(png) > 200)
    after = _reachable_pixels(shot)  # once SwiftShader has rendered the points
    assert before < 20 and after > 200, (before, after)

    # the next plan's path in the view's pixels: its line and frustums in the path colour (the reach layer off)
    api.put(f"/api/scene/{viewer}/layers", json={"reach": False, "path": True}).raise_for_status()
    mark = len(tab.frames)
    api.post(f"/api/sessions/{sid}/plan").raise_for_status()
    tab.wait(lambda: _path_drawn(tab, mark), timeout_ms=60_000)
    api.post(f"/api/scene/{viewer}/camera", json={"position": [0.9, -0.9, 1.1], "look_at": [0.0, 0.0, 0.15]})
    path_shot = shot_until(  # SwiftShader: the path rendered
        tab.page, lambda: _scene_shot(tab, output_dir / "arm-path.png"), lambda png: _path_pixels(png) > 500
    )
    path_after = _path_pixels(path_shot)
    assert path_before < 50 and path_after > 500, (path_before, path_after)
    draw_viewer(tab.page, on=False)
