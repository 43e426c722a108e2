"""Debugging a fit in the page (headless Chromium, live server, the session's worker): the clusters layer's frames
carry per-voxel colours that match the fit's labels (decoded viser buffers); the layer bar shows a viewer's real
layers after a PUT from outside the page; a click on an ellipsoid in the 3D view selects its Fit row; a T clicked
on the BIC chart draws that many ellipsoids of that kind and leaves the plan as it was."""

from __future__ import annotations

import httpx
import numpy as np
import pytest
from playwright.sync_api import BrowserContext, expect

from tests.e2e.conftest import draw_viewer
from tests.e2e.test_workbench_browser import Tab, _state
from tests.helpers import SMALL
from tests.servers import LiveServer
from tests.viewer_buffers import decode_frame_arrays

pytestmark = pytest.mark.e2e  # tests/conftest.py: the long groups are handed out first


class _Decoded:
    """The tab's viewer frames decoded with their buffers, each frame once (polling re-reads only new ones)."""

    def __init__(self, tab: Tab) -> None:
        self.tab = tab
        self.messages: list[list[dict]] = []

    def clouds(self, start: int = 0) -> dict[str, np.ndarray]:
        """Per kind, the colours (N, 3) of the last /clusters/<kind>/voxels point cloud since frame ``start``."""
        for data in self.tab.frames[len(self.messages) :]:
            self.messages.append(decode_frame_arrays(data))
        out = {}
        for frame in self.messages[start:]:
            for m in frame:
                name = m.get("name", "")
                if name.startswith("/clusters/") and name.endswith("/voxels") and "PointCloud" in m.get("type", ""):
                    out[name.split("/")[2]] = np.asarray(m["props"]["colors"]).reshape(-1, 3)
        return out


def _first_hit(origin: np.ndarray, direction: np.ndarray, ellipsoids: list, inflate: float = 1.0) -> list[float]:
    """Per ellipsoid, where the ray enters it (inf: missed); axes scaled by ``inflate``."""
    out = []
    for e in ellipsoids:
        A = (e.rotation / (inflate * e.axes) ** 2) @ e.rotation.T
        y = origin - e.center
        a, b, c = direction @ A @ direction, 2 * direction @ A @ y, y @ A @ y - 1
        disc = b * b - 4 * a * c
        out.append(np.inf if disc < 0 else max(0.0, (-b - np.sqrt(disc)) / (2 * a)))
    return out


def _camera_on_one(plan) -> tuple[str, np.ndarray, np.ndarray]:
    """(label, eye, look_at): a camera whose central ray reaches one ellipsoid before any other (10 % margin)."""
    labelled, counts = [], {"occupied": 0, "frontier": 0}
    for e in plan.ellipsoids:
        labelled.append((f"{e.kind[0].upper()}{counts[e.kind]}", e))
        counts[e.kind] += 1
    ells = [e for _, e in labelled]
    center = np.mean([e.center for e in ells], axis=0)
    for label, e in sorted(labelled, key=lambda le: -float(np.prod(le[1].axes))):
        for u in ([1, -1, 1], [-1, -1, 1], [1, 1, 1], [-1, 1, 1], [0, 0, 1], [1, 0, 0.3], [0, -1, 0.3]):
            out = np.asarray(u, float) + 2.0 * (e.center - center)
            out /= np.linalg.norm(out)
            eye = e.center + 0.3 * out
            d = -out
            mine = _first_hit(eye, d, [e])[0]
            others = _first_hit(eye, d, [x for x in ells if x is not e], inflate=1.1)
            if np.isfinite(mine) and all(t > mine + 0.005 for t in others):
                return label, eye, e.center
    raise AssertionError("no camera sees one ellipsoid first")


def test_debugging_a_fit(live_server: LiveServer, browser_context: BrowserContext) -> None:
    api = httpx.Client(base_url=live_server.url, timeout=120)
    sid = api.post("/api/sessions", json={"model": "l-block", "config": SMALL}).json()["id"]
    api.post(f"/api/sessions/{sid}/capture")
    plan_id = api.post(f"/api/sessions/{sid}/plan").json()["plan_id"]
    tab = Tab(browser_context, f"{live_server.url}/?session={sid}")
    page = tab.page
    _state(tab, "planned")
    page.wait_for_function("() => Boolean(S.viewer)", timeout=60_000)  # the page opens its viewer after the state
    viewer = page.evaluate("S.viewer")
    tab.wait(lambda: api.get(f"/api/scene/{viewer}").json()["connected"])
    plan = live_server.registry.get(sid).plan_for().plan

    # the clusters layer from the layer bar: per-voxel colours = the colour of each voxel's cluster (its label)
    tab.wait(lambda: any(m.get("name") == "/candidates" for m in tab.messages()))
    page.locator("#layers input[data-layer='clusters']").check(timeout=60_000)  # a loaded machine: SwiftShader is slow
    decoded = _Decoded(tab)
    tab.wait(lambda: len(decoded.clouds()) == 2)
    fit = api.get(f"/api/scene/{viewer}/fit").json()
    clouds = decoded.clouds()
    for kind in ("occupied", "frontier"):
        labels = next(f for f in plan.fits if f.kind == kind).labels
        color_of = {r["index"]: r["color"] for r in fit["rows"] if r["kind"] == kind}
        assert len(labels) == len(clouds[kind]) > 0
        assert np.array_equal(clouds[kind], np.array([color_of[int(k)] for k in labels]))
    expect(page.locator("#fit tbody tr")).to_have_count(len(plan.ellipsoids))

    # layers set from outside the page: the layer bar shows the viewer's real state
    hide = dict.fromkeys(("occupied", "frontier", "unknown", "ellipsoids", "candidates", "nbv", "views", "bbox",
                          "sectors", "cloud", "turntable"), False)  # fmt: skip
    api.put(f"/api/scene/{viewer}/layers", json=hide)
    real = api.get(f"/api/scene/{viewer}").json()["layers"]
    for name, on in real.items():
        if name != "gizmo":
            box = page.locator(f"#layers input[data-layer='{name}']")
            (expect(box).to_be_checked() if on else expect(box).not_to_be_checked())

    # a click on an ellipsoid in the 3D view selects its Fit row (picking needs drawn frames)
    draw_viewer(page)
    label, eye, look_at = _camera_on_one(plan)
    api.post(f"/api/scene/{viewer}/camera", json={"position": eye.tolist(), "look_at": look_at.tolist()})
    close = page.frame_locator("#viewer").locator("button.mantine-Notification-closeButton")
    if close.count():
        close.first.dispatch_event("click")
    page.wait_for_timeout(1500)  # SwiftShader: the camera move rendered
    box = page.locator("#viewer").bounding_box()
    assert box is not None
    row = page.locator(f"#fit tbody tr.focused[data-label='{label}']")
    for _ in range(3):  # SwiftShader may still be drawing the camera move: click again, as a person would
        page.mouse.click(box["x"] + box["width"] / 2, box["y"] + box["height"] / 2)
        for _ in range(50):
            if row.count():
                break
            page.wait_for_timeout(100)
        if row.count():
            break
    expect(row).to_have_count(1)
    expect(page.locator("#fit tbody tr.focused")).to_have_count(1)
    assert api.get(f"/api/scene/{viewer}/fit").json()["focus"] == label
    # the inspector and the Fit panel mark each other's rows: a click on an inspector row focuses that ellipsoid
    first = page.locator("#breakdown tbody tr").first
    other = first.locator("td").first.inner_text()
    first.click()
    expect(page.locator(f"#fit tbody tr.focused[data-label='{other}']")).to_have_count(1, timeout=15_000)
    expect(page.locator(f"#breakdown tbody tr.focused[data-label='{other}']")).to_have_count(1)

    # a T on the BIC chart: that many ellipsoids of that kind in this tab, the plan unchanged
    chosen = max(plan.fits, key=lambda f: len(f.bic))  # the kind with the most T evaluated
    kind = chosen.kind
    t = max(t for t, _ in chosen.bic if t != chosen.t_chosen)
    mark = len(tab.frames)
    if not page.locator("#charts-box").evaluate("(d) => d.open"):  # folded on a short window
        page.locator("#charts-box > summary").click()
    page.locator(f"#chart-bic circle[data-series='{kind}'][data-x='{t}']").click()
    expect(page.locator(f"#fit-kinds [data-kind='{kind}']")).to_contain_text(f"fit at T={t}", timeout=60_000)
    expect(page.locator(f"#chart-bic circle.fit-picked[data-kind='{kind}']")).to_have_attribute("data-t", str(t))

    def spheres() -> set[str]:
        return {
            m["name"] for m in tab.messages(mark)
            if m.get("name", "").startswith(f"/clusters/{kind}/") and "Icosphere" in m.get("type", "")
        }  # fmt: skip

    tab.wait(lambda: len(spheres()) >= t)
    assert spheres() == {f"/clusters/{kind}/{i}" for i in range(t)}
    expect(page.locator(f"#fit tbody tr[data-kind='{kind}']")).to_have_count(t)
    expect(page.locator("#plan-id")).to_have_text(f"plan {plan_id}")
    status = api.get(f"/api/sessions/{sid}").json()
    assert status["pending_plan"]["plan_id"] == plan_id and status["state"] == "planned"
    page.locator(f"#fit-back-{kind}").click()
    expect(page.locator("#chart-bic circle.fit-picked")).to_have_count(0)
    expect(page.locator(f"#fit tbody tr[data-kind='{kind}']")).to_have_count(
        sum(e.kind == kind for e in plan.ellipsoids)
    )
