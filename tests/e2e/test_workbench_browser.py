"""The workbench page in real Chromium tabs against a live server (uvicorn + viser, real planner, simulated cell).

- two tabs on two sessions: each tab's viewer websocket frames (decoded msgpack) carry only its own session's
  nodes, through create, capture, plan, approve and auto in the other tab; reload keeps a tab on its session;
  a tab without a session shows the picker;
- the page is live from pushed events: no request to the status route during a 4-step auto run, every step
  shown;
- the loop's helpers: keyboard help, the full sortable candidate table, the confirmation of an ineligible
  approve (recorded as an override), discard, Auto disabled with its reason, delete with confirmation.
"""

from __future__ import annotations

import re
import threading
from typing import Any

import httpx
import pytest
from playwright.sync_api import BrowserContext, Page, expect

from tests.e2e.forms import fill_small_form
from tests.helpers import SMALL
from tests.servers import LiveServer
from tests.viewer_wire import decode_frame, session_labels, session_nodes

pytestmark = pytest.mark.e2e  # tests/conftest.py: the long groups are handed out first

LONG = {**SMALL, "termination": {"max_views": 30, "stop_without_frontier": False}}
AUTO_STEPS = 4
"""Steps of the auto run whose every step the page must show (each one pushed, none polled)."""


class Tab:
    """A page of ``context`` at ``url`` that records the viewer's websocket frames and every request."""

    def __init__(self, context: BrowserContext, url: str) -> None:
        self.page: Page = context.new_page()
        self.frames: list[bytes] = []
        self.requests: list[str] = []
        self.page.on("websocket", self._socket)
        self.page.on("request", lambda r: self.requests.append(r.url))
        self.page.goto(url)

    def _socket(self, ws: Any) -> None:
        if "/api/events" in ws.url:
            return
        ws.on("framereceived", lambda payload: self.frames.append(payload) if isinstance(payload, bytes) else None)

    def messages(self, start: int = 0) -> list[dict[str, Any]]:
        return [m for data in self.frames[start:] for m in decode_frame(data)]

    def wait(self, predicate: Any, timeout_ms: int = 30_000) -> None:
        """Wait for ``predicate()`` while the page keeps receiving events (never time.sleep)."""
        for _ in range(timeout_ms // 100):
            if predicate():
                return
            self.page.wait_for_timeout(100)
        raise AssertionError("timed out")


def _state(tab: Tab, text: str, timeout: int = 60_000) -> None:
    expect(tab.page.locator("#state")).to_have_text(text, timeout=timeout)


def test_two_tabs_show_only_their_own_session(live_server: LiveServer, browser_context: BrowserContext) -> None:
    api = httpx.Client(base_url=live_server.url, timeout=120)
    a = api.post("/api/sessions", json={"model": "l-block", "config": SMALL}).json()["id"]
    api.post(f"/api/sessions/{a}/capture")
    api.post(f"/api/sessions/{a}/plan")
    ta = Tab(browser_context, f"{live_server.url}/?session={a}")
    _state(ta, "planned")
    ta.wait(lambda: session_labels(ta.messages()) == {f"session {a}"} and "/candidates" in session_nodes(ta.messages()))
    mark = len(ta.frames)

    # tab B: no id -> the picker; create a session there (it lists A), then scan it through B's page
    tb = Tab(browser_context, f"{live_server.url}/")
    expect(tb.page.locator("#picker")).to_be_visible()
    expect(tb.page.locator(f"#picker a[data-session='{a}']")).to_be_visible()
    tb.page.select_option("#model", "two-boxes")
    fill_small_form(tb.page)
    tb.page.click("#create")
    tb.page.wait_for_url(re.compile(r"\?session=[0-9a-f]{8}"))
    b = re.search(r"session=([0-9a-f]{8})", tb.page.url).group(1)  # type: ignore[union-attr]
    _state(tb, "new")
    tb.page.click("#capture")
    _state(tb, "ready")
    tb.page.click("#plan")
    _state(tb, "planned")
    tb.page.click("#approve")
    expect(tb.page.locator("#iteration")).to_have_text("2", timeout=60_000)
    tb.page.fill("#auto-count", "2")
    tb.page.click("#auto")
    expect(tb.page.locator("#iteration")).to_have_text("4", timeout=60_000)
    tb.wait(lambda: "/views/4/frustum" in session_nodes(tb.messages()))

    # A's viewer received nothing of it; each tab's scene names only its own session; A's panels are A's
    ta.page.wait_for_timeout(500)
    assert session_nodes(ta.messages(mark)) == set()
    assert session_labels(ta.messages()) == {f"session {a}"}
    assert session_labels(tb.messages()) == {f"session {b}"}
    expect(ta.page.locator("#session-info")).to_contain_text(a)
    expect(ta.page.locator("#iteration")).to_have_text("1")
    _state(ta, "planned")

    # reload: A stays on A, its new viewer is bound to A again
    ta.frames.clear()
    ta.page.reload()
    _state(ta, "planned")
    expect(ta.page.locator("#session-info")).to_contain_text(a)
    ta.wait(lambda: "/candidates" in session_nodes(ta.messages()))
    assert session_labels(ta.messages()) == {f"session {a}"}


def test_the_page_is_pushed_every_step_of_auto_without_polling(
    live_server: LiveServer, browser_context: BrowserContext
) -> None:
    api = httpx.Client(base_url=live_server.url, timeout=120)
    sid = api.post("/api/sessions", json={"model": "l-block", "config": LONG}).json()["id"]
    api.post(f"/api/sessions/{sid}/capture")
    tab = Tab(browser_context, f"{live_server.url}/?session={sid}")
    _state(tab, "ready")
    tab.page.evaluate(
        """() => { window.__steps = [];
        new MutationObserver(() => window.__steps.push(document.getElementById('iteration').textContent))
          .observe(document.getElementById('iteration'), {childList: true, characterData: true, subtree: true}); }"""
    )
    tab.requests.clear()
    tab.page.fill("#auto-count", str(AUTO_STEPS))
    tab.page.click("#auto")
    expect(tab.page.locator("#busy")).to_contain_text("auto: step", timeout=10_000)
    expect(tab.page.locator("#iteration")).to_have_text(str(1 + AUTO_STEPS), timeout=120_000)
    expect(tab.page.locator("#state")).not_to_have_text("auto", timeout=30_000)
    steps = tab.page.evaluate("window.__steps")
    shown = [s for i, s in enumerate(steps) if (i == 0 or s != steps[i - 1]) and s != "1"]
    assert shown == [str(k) for k in range(2, 2 + AUTO_STEPS)]  # every step, in order
    status_route = re.compile(rf"/api/sessions/{sid}(\?|$)")
    assert not [u for u in tab.requests if status_route.search(u)], "the page polled the status route"

    # compare: a second session on the same object with another planner, side by side, each a link to its tab
    other = api.post("/api/sessions", json={"model": "l-block", "config": LONG, "planner": "random"}).json()["id"]
    api.post(f"/api/sessions/{other}/capture")
    api.post(f"/api/sessions/{other}/step", json={"count": 2})
    cmp = Tab(browser_context, f"{live_server.url}/?compare={sid},{other}")
    expect(cmp.page.locator("#compare")).to_be_visible()
    expect(cmp.page.locator("#compare tbody tr")).to_have_count(2)
    expect(cmp.page.locator("#compare tbody")).to_contain_text("random")
    expect(cmp.page.locator(f"#compare a[href*='session={other}']")).to_be_visible()
    assert cmp.page.locator("#cmp-coverage path").count() == 2


def test_the_loop_helpers(live_server: LiveServer, browser_context: BrowserContext) -> None:
    api = httpx.Client(base_url=live_server.url, timeout=120)
    sid = api.post(
        "/api/sessions", json={"model": "l-block", "config": {**SMALL, "termination": {"max_views": 2}}}
    ).json()["id"]
    api.post(f"/api/sessions/{sid}/capture")
    api.post(f"/api/sessions/{sid}/plan")
    tab = Tab(browser_context, f"{live_server.url}/?session={sid}")
    page = tab.page
    _state(tab, "planned")
    # help overlay from the keyboard
    page.keyboard.press("?")
    expect(page.locator("#help")).to_be_visible()
    expect(page.locator("#help-keys")).to_contain_text("approve")
    page.keyboard.press("Escape")
    expect(page.locator("#help")).to_be_hidden()
    # every candidate, paged, with the reason an ineligible one is not eligible
    expect(page.locator("#page-info")).to_contain_text("60 candidates")
    page.click("#candidates th[data-sort='reason']")
    page.click("#candidates th[data-sort='reason']")  # descending: the ineligible ones first
    expect(page.locator("#candidates tbody tr").first).to_have_class(re.compile("ineligible"))
    # a selection made elsewhere (a sphere in 3D, another tab) turns the table to its row
    index = next(
        c["index"] for c in api.get(f"/api/sessions/{sid}/candidates").json() if c["reason"] == "sector locked"
    )
    api.put(f"/api/sessions/{sid}/selection", json={"index": index})
    row = page.locator(f"#candidates tbody tr[data-index='{index}']")
    expect(row).to_have_class(re.compile("selected"))
    expect(row.locator("td.why")).to_have_text("sector locked")
    expect(page.locator("#selected-label")).to_contain_text(f"candidate {index}")
    # an ineligible approve asks first: dismissed, nothing moves; accepted, an override is recorded
    page.once("dialog", lambda d: d.dismiss())
    page.keyboard.press("a")
    page.wait_for_timeout(500)
    expect(page.locator("#iteration")).to_have_text("1")
    page.once("dialog", lambda d: d.accept())
    page.click("#approve")
    expect(page.locator("#iteration")).to_have_text("2", timeout=60_000)
    decisions = api.get(f"/api/sessions/{sid}/export").json()["decisions"]
    assert decisions[-1]["kind"] == "override" and decisions[-1]["index"] == index
    # the planner's stop (max_views 2): Auto is off and says why
    expect(page.locator("#auto")).to_be_disabled()
    expect(page.locator("#auto-why")).to_contain_text("the planner stopped")
    # discard the last view (confirmed): back to one view, Auto possible again
    expect(page.locator("#discard")).to_be_enabled(timeout=30_000)
    page.once("dialog", lambda d: d.accept())
    page.keyboard.press("d")
    expect(page.locator("#iteration")).to_have_text("1", timeout=60_000)
    expect(page.locator("#auto")).to_be_enabled(timeout=30_000)
    # delete, confirmed: back to the picker, the session is gone
    page.once("dialog", lambda d: d.accept())
    page.click("#delete")
    expect(page.locator("#picker")).to_be_visible(timeout=20_000)
    assert api.get(f"/api/sessions/{sid}").status_code == 404


HEAVY = {
    "voxel": {"resolution": 0.01},
    "cluster": {"search": "exhaustive", "t_min": 1, "t_max": 60, "max_iter": 1000, "tol": 1e-8},
    "candidates": {"count": 833, "parallels": 30},
}
"""A plan of about a minute on 2 cores (60 exhaustive fits per voxel kind)."""


def test_long_operations_show_their_progress_and_stop(
    live_server: LiveServer, browser_context: BrowserContext, tmp_path: Any
) -> None:
    import trimesh

    api = httpx.Client(base_url=live_server.url, timeout=120)
    sid = api.post("/api/sessions", json={"model": "l-block", "config": HEAVY}).json()["id"]
    api.post(f"/api/sessions/{sid}/capture")
    tab = Tab(browser_context, f"{live_server.url}/?session={sid}")
    page = tab.page
    _state(tab, "ready")
    # a long plan: its stage, k of n, the values of T done, a percent; Stop kills it and says so
    page.click("#plan")
    progress = page.locator("#progress")
    expect(progress).to_contain_text(re.compile(r"planning · fit occupied \(3 of 6\) · \d+ / 60"), timeout=60_000)
    expect(page.locator("#stop")).to_be_visible()
    page.click("#stop")
    expect(page.locator("#notice")).to_contain_text("the plan was stopped", timeout=10_000)
    _state(tab, "ready", timeout=10_000)
    expect(progress).to_be_hidden()
    assert api.get(f"/api/sessions/{sid}").json()["pending_plan"] is None
    # a create on a mesh file: its stages under the button, and Cancel (nothing created). The server's create
    # is held as it starts its second stage until the page's DELETE has answered (the real create, its real
    # cancel: a 50 MB OBJ would race the click, its parsing starving the server's event loop of the GIL)
    trimesh.creation.icosphere(subdivisions=6, radius=0.05).export(tmp_path / "ball.obj")
    hold = threading.Event()

    def hold_first_stage(progress_id: str, progress: Any) -> None:
        if progress is not None and progress.stage == "reading the mesh":
            hold.wait(30)

    live_server.registry.creations.listeners.append(hold_first_stage)
    page.reload()
    _state(tab, "ready")  # the page has opened its session (its layout settled): the click lands on the summary
    page.locator("#create-box > summary").click()
    expect(page.locator("#model")).to_be_visible()
    page.locator("#model").select_option("ball.obj")
    sessions = len(api.get("/api/sessions").json())
    page.click("#create")
    expect(page.locator("#create-progress")).to_contain_text("creating · checking the file (1 of 6)")
    expect(page.locator("#create-cancel")).to_be_visible()
    with page.expect_response(lambda r: "/api/creations/" in r.url) as cancelled:
        page.click("#create-cancel")
    assert cancelled.value.status == 204
    hold.set()
    expect(page.locator("#notice")).to_contain_text("cancelled", timeout=30_000)
    expect(page.locator("#create-progress")).to_be_hidden()
    assert len(api.get("/api/sessions").json()) == sessions and page.url.endswith(f"session={sid}")
