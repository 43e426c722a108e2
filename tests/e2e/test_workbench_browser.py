"""The supervised loop in real headless Chromium: create, capture, plan, click a candidate in the 3D view, approve.

The click is a real mouse click on the viser canvas inside the page's iframe: the
test points the viewer's camera at a chosen candidate (``POST /api/scene/camera``),
reads back the camera the browser reports (pose, fov, canvas size), projects the
candidate into it, and clicks that pixel. The scene is kept small (2 cm voxels,
60 candidates, T in [2, 6]) because SwiftShader renders on the CPU.
"""

from __future__ import annotations

import time
from pathlib import Path
from typing import TYPE_CHECKING, Any

import httpx
import numpy as np
import pytest
from playwright.sync_api import Page, expect

from devices.protocols import CaptureError
from planner import Pose

if TYPE_CHECKING:
    from tests.e2e.conftest import LiveServer
from tests.helpers import wait_until

pytestmark = [pytest.mark.e2e, pytest.mark.slow]

SMALL_PARAMS = {
    "p-resolution": "0.02",
    "p-count": "60",
    "p-parallels": "4",
    "p-tmin": "2",
    "p-tmax": "6",
    "p-revisit": "20",
}


def wait_for(fn, timeout: float = 30.0) -> Any:
    """Until ``fn`` returns something truthy (the server sends these tests no event); fail after ``timeout``."""
    return wait_until(fn, timeout, getattr(fn, "__name__", str(fn)))


def project(camera: dict[str, Any], point: np.ndarray) -> tuple[float, float]:
    """Pixel (u, v) of a world point in a viser client camera (OpenCV axes, vertical fov, square pixels)."""
    T = Pose.from_wxyz(camera["wxyz"], camera["position"])
    x, y, z = T.inverse().apply(point[None, :])[0]
    assert z > 0, "the point is behind the viewer's camera"
    W, H = camera["image_width"], camera["image_height"]
    f = (H / 2.0) / np.tan(camera["fov"] / 2.0)
    return W / 2.0 + f * x / z, H / 2.0 + f * y / z


def viewer_canvas_box(page: Page) -> dict[str, float]:
    """Bounding box (page coordinates) of the largest canvas inside the viser iframe."""
    canvases = page.frame_locator("#viewer").locator("canvas")
    wait_for(lambda: canvases.count() > 0)
    boxes = [canvases.nth(i).bounding_box() for i in range(canvases.count())]
    boxes = [b for b in boxes if b is not None]
    return max(boxes, key=lambda b: b["width"] * b["height"])


def test_supervised_loop_in_the_browser(live_server: LiveServer, browser_page: Page, output_dir: Path) -> None:
    t_start = time.perf_counter()
    page, base = browser_page, live_server.url
    api = httpx.Client(base_url=base, timeout=60)
    page.goto(base + "/")
    expect(page.locator("#health")).to_have_text("server ok", timeout=20_000)
    viewer_url = api.get("/api/viewer").json()["url"]
    expect(page.locator("#viewer")).to_have_attribute("src", viewer_url)

    # 1. create a session with small parameters, 2. capture
    page.select_option("#model", "l-block")
    for field, value in SMALL_PARAMS.items():
        page.fill(f"#{field}", value)
    page.click("#create")
    expect(page.locator("#state")).to_have_text("new", timeout=20_000)
    sid = page.locator("#session-select").input_value()
    assert api.get(f"/api/sessions/{sid}").json()["model"] == "l-block"
    config = api.get(f"/api/sessions/{sid}/export").json()["config"]
    assert config["partitions"]["revisit_deg"] == 20 and config["voxel"]["resolution"] == 0.02
    page.click("#capture")
    expect(page.locator("#state")).to_have_text("ready", timeout=30_000)
    expect(page.locator("#iteration")).to_have_text("1")

    # 3. plan: the candidate list fills
    page.click("#plan")
    expect(page.locator("#state")).to_have_text("planned", timeout=60_000)
    expect(page.locator("#candidates tbody tr").first).to_be_visible()
    status = api.get(f"/api/sessions/{sid}").json()
    plan_id, best = status["pending_plan"]["plan_id"], status["pending_plan"]["best"]["index"]
    assert status["selected"] == best

    # 4. click another eligible candidate in the 3D scene
    cands = api.get(f"/api/sessions/{sid}/candidates").json()
    target = next(c for c in sorted(cands, key=lambda c: -c["score"]) if c["eligible"] and c["index"] != best)
    k = target["index"]
    position = np.array(target["pose"]["position"])
    wait_for(lambda: api.get("/api/scene/cameras").json(), timeout=60)  # the viser client connected
    assert api.post("/api/scene/camera", json={"candidate": k, "distance": 0.3}).json()["clients"] >= 1

    def camera_on_target() -> dict[str, Any] | None:
        for cam in api.get("/api/scene/cameras").json():
            if (
                np.allclose(cam["look_at"], position, atol=1e-3)
                and abs(np.linalg.norm(np.subtract(cam["position"], position)) - 0.3) < 1e-3
            ):
                return cam
        return None

    camera = wait_for(camera_on_target, timeout=30)
    page.wait_for_timeout(1000)  # let SwiftShader render the new view before clicking (page events keep flowing)
    u, v = project(camera, position)
    box = viewer_canvas_box(page)
    x = box["x"] + u * box["width"] / camera["image_width"]
    y = box["y"] + v * box["height"] / camera["image_height"]
    page.mouse.click(x, y)
    wait_for(lambda: api.get(f"/api/sessions/{sid}").json()["selected"] == k, timeout=30)
    expect(page.locator("#selected-label")).to_contain_text(f"candidate {k}", timeout=10_000)
    expect(page.locator("#projection")).to_be_visible()
    expect(page.locator(f"#candidates tr.selected[data-index='{k}']")).to_have_count(1)

    # 5. approve: the robot moves to the clicked candidate
    page.click("#approve")
    expect(page.locator("#iteration")).to_have_text("2", timeout=60_000)
    expect(page.locator("#state")).to_have_text("ready", timeout=30_000)
    doc = api.get(f"/api/sessions/{sid}/export").json()
    decision = doc["decisions"][-1]
    assert (decision["plan_id"], decision["index"], decision["kind"]) == (plan_id, k, "override")
    assert np.allclose(doc["iterations"][-1]["pose"]["position"], position, atol=1e-6)

    # the scene holds ellipsoids and candidates drawn from the plan
    nodes = api.get("/api/scene").json()["nodes"]
    assert any(n.startswith("/ellipsoids/occupied/") for n in nodes)
    assert any(n.startswith("/ellipsoids/frontier/") for n in nodes)
    assert "/candidates" in nodes and "/views/2/frustum" in nodes

    shot = output_dir / "workbench.png"
    page.screenshot(path=str(shot))
    assert shot.stat().st_size > 10_000
    print(f"e2e loop took {time.perf_counter() - t_start:.1f} s; screenshot {shot}")


def test_api_docs_render_offline(live_server: LiveServer, browser_page: Page, output_dir: Path) -> None:
    """Swagger UI renders the API with every request outside this server blocked (as on a machine offline)."""
    page = browser_page
    outside: list[str] = []

    def only_local(route, request) -> None:
        if request.url.startswith(live_server.url):
            route.continue_()
        else:
            outside.append(request.url)
            route.abort()

    page.route("**/*", only_local)
    page.goto(f"{live_server.url}/docs")
    ops = page.locator(".opblock")
    expect(ops.first).to_be_visible(timeout=30_000)
    assert ops.count() >= 25
    expect(page.locator(".swagger-ui .title").first).to_contain_text("NBV workbench")
    assert outside == []
    page.screenshot(path=str(output_dir / "api-docs.png"))


def test_the_page_carries_the_token(tmp_path: Path, browser_page: Page) -> None:
    """A server with a token: the page opened with ``?token=`` sends it on every call; opened without it, the
    API refuses it. (The viewer link's token is checked in tests/app/test_security.py; no 3D scene here.)"""
    from app.settings import AppSettings
    from tests.e2e.conftest import free_port, running_server

    token = "browser-test-token-123"
    settings = AppSettings(port=free_port(), data_dir=tmp_path / "data", models_dir=tmp_path, token=token, scene=False)
    page = browser_page
    with running_server(settings) as server:
        page.goto(f"{server.url}/")
        expect(page.locator("#health")).to_have_text("server unreachable", timeout=30_000)
        page.goto(f"{server.url}/?token={token}")
        expect(page.locator("#health")).to_have_text("server ok", timeout=30_000)
        expect(page.locator("#model option")).not_to_have_count(0)
        page.get_by_test_id("create").click()
        expect(page.get_by_test_id("state")).to_have_text("new", timeout=30_000)
        assert len(server.app.state.registry.list()) == 1


def test_resume_and_retry_from_the_page(tmp_path: Path, browser_page: Page) -> None:
    """A session journaled by an earlier server shows as interrupted with a Resume button; after a fault, Retry."""
    from app.settings import AppSettings
    from tests.e2e.conftest import free_port, running_server

    small = {
        "voxel": {"resolution": 0.02},
        "candidates": {"count": 60, "parallels": 4},
        "cluster": {"t_min": 2, "t_max": 6},
    }
    settings = AppSettings(data_dir=tmp_path / "data", models_dir=tmp_path, scene=False, fault_api=True)
    faults = {"schedule": [{"kind": "capture_failure", "at": 2}]}
    with running_server(settings.replace(port=free_port())) as first:
        api = httpx.Client(base_url=first.url, timeout=60)
        sid = api.post("/api/sessions", json={"config": small, "faults": faults}).json()["id"]
        api.post(f"/api/sessions/{sid}/capture")
        api.post(f"/api/sessions/{sid}/plan")
    page = browser_page
    with running_server(settings.replace(port=free_port())) as second:
        page.goto(f"{second.url}/")
        expect(page.get_by_test_id("state")).to_have_text("interrupted", timeout=30_000)
        expect(page.get_by_test_id("plan")).to_be_disabled()
        page.get_by_test_id("resume").click()
        expect(page.get_by_test_id("state")).to_have_text("planned", timeout=30_000)
        expect(page.get_by_test_id("resume")).to_be_hidden()
        second.app.state.registry.get(sid).cell.camera.fail_next = CaptureError("lens cap on")
        page.get_by_test_id("approve").click()
        expect(page.get_by_test_id("state")).to_have_text("error", timeout=30_000)
        expect(page.locator("#error")).to_contain_text("lens cap on")
        page.get_by_test_id("retry").click()
        expect(page.get_by_test_id("iteration")).to_have_text("2", timeout=30_000)
        expect(page.get_by_test_id("state")).to_have_text("ready")
        expect(page.get_by_test_id("retry")).to_be_hidden()
