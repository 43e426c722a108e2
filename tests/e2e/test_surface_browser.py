"""The surface layer in the page (headless Chromium): after 2 views, turning the layer on in the layer bar sends the
session's simplified surface to this tab's viewer as the ``/surface`` mesh; the export offers it as PLY, OBJ, GLB."""

from __future__ import annotations

import httpx
import pytest
from playwright.sync_api import BrowserContext, expect

from tests.e2e.test_workbench_browser import Tab, _state
from tests.helpers import SMALL
from tests.servers import LiveServer

pytestmark = pytest.mark.e2e  # tests/conftest.py: the long groups are handed out first


def test_the_surface_layer_after_two_views(live_server: LiveServer, browser_context: BrowserContext) -> None:
    api = httpx.Client(base_url=live_server.url, timeout=120)
    sid = api.post("/api/sessions", json={"model": "box", "config": SMALL}).json()["id"]
    api.post(f"/api/sessions/{sid}/capture")
    assert api.post(f"/api/sessions/{sid}/step", json={"count": 1}).json()["iteration"] == 2
    layer_triangles = api.get(f"/api/sessions/{sid}/export").json()["surface"]["layer_triangles"]
    assert layer_triangles > 0
    tab = Tab(browser_context, f"{live_server.url}/?session={sid}")
    _state(tab, "ready")
    checkbox = tab.page.locator("#layers input[data-layer='surface']")
    expect(checkbox).not_to_be_checked()  # off by default: nothing of it sent yet
    tab.wait(lambda: any(m.get("name") == "/candidates" or m.get("name") == "/cloud/0" for m in tab.messages()))
    assert not [m for m in tab.messages() if m.get("name") == "/surface"]
    checkbox.check()

    def surface_meshes() -> list[dict]:
        return [m for m in tab.messages() if m.get("name") == "/surface" and "Mesh" in m.get("type", "")]

    tab.wait(lambda: len(surface_meshes()) == 1)
    props = surface_meshes()[0]["props"]
    assert props["faces"]["nbytes"] == 12 * layer_triangles and props["vertices"]["nbytes"] > 0
    for fmt in ("ply", "obj", "glb"):
        link = tab.page.locator(f"#export-surface-{fmt}")
        href = link.get_attribute("href") or ""
        assert href.endswith(f"/api/sessions/{sid}/surface.ply?format={fmt}")
        r = api.get(href)
        assert r.status_code == 200 and len(r.content) > 1000
