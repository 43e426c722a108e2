"""The ``tour`` planner in the page, real Chromium against a live server: its predicted tour drawn in
the tab's 3D view (numbered frustums and the path through them), each candidate's move time and tour place in
the table, and the predicted robot time to done."""

from __future__ import annotations

import itertools

import httpx
import pytest
from playwright.sync_api import BrowserContext, expect

from tests.e2e.test_workbench_browser import Tab
from tests.helpers import SMALL
from tests.servers import LiveServer
from tests.viewer_wire import session_nodes

pytestmark = pytest.mark.e2e  # tests/conftest.py: the long groups are handed out first

CONFIG = {
    **SMALL,
    "voxel": {"resolution": 0.01},
    "tour": {"min_gain": 0.0, "horizon": 4, "lazy_reach": False, "opening": "ring", "cover_max_elevation_deg": 90},
}
"""Few candidates (fast), a map fine enough for several views to add frontier, a tour of all of them (up to 4; every
elevation: of the 4 parallels of these 60 candidates only the lowest is under the default's 25 degrees, and after
the ring their cover is a single view, a tour too short to draw a path); every candidate's reachability
asked (not only the tour's), so every row of the table has its move time; the ring opening's two views first."""


def tour_rows(api: httpx.Client, sid: str) -> list[dict]:
    rows = api.get(f"/api/sessions/{sid}/candidates").json()
    return sorted((c for c in rows if c["tour_order"] is not None), key=lambda c: c["tour_order"])


def test_the_page_draws_the_tour_and_its_move_times(live_server: LiveServer, browser_context: BrowserContext) -> None:
    api = httpx.Client(base_url=live_server.url, timeout=120)
    sid = api.post("/api/sessions", json={"model": "l-block", "config": CONFIG, "planner": "tour"}).json()["id"]
    api.post(f"/api/sessions/{sid}/capture").raise_for_status()
    api.post(f"/api/sessions/{sid}/plan").raise_for_status()
    ring = tour_rows(api, sid)  # the ring opening: one low view round from the first
    assert [(c["tour_order"], c["tour_method"], c["best"]) for c in ring] == [(1, "ring", True)]
    assert ring[0]["elevation_deg"] <= 30.0 + 1e-6 and ring[0]["move_seconds"] == ring[0]["tour_seconds"] > 0

    tab = Tab(browser_context, f"{live_server.url}/?session={sid}")
    expect(tab.page.locator("#state")).to_have_text("planned", timeout=60_000)
    expect(tab.page.locator("#tour-info")).to_have_text(
        f"ring opening: a low view round from the first, then the tour; move {ring[0]['tour_seconds']:.1f} s"
    )
    tab.wait(lambda: "/tour/1/frustum" in session_nodes(tab.messages()))

    api.post(f"/api/sessions/{sid}/step", json={"count": 2}).raise_for_status()  # both views of the ring taken
    api.post(f"/api/sessions/{sid}/plan").raise_for_status()
    tour = tour_rows(api, sid)
    assert len(tour) >= 2 and tour[0]["best"] and {c["tour_method"] for c in tour} <= {"exact", "lkh"}
    assert [c["tour_order"] for c in tour] == list(range(1, len(tour) + 1))
    assert all(c["eligible"] and c["move_seconds"] > 0 for c in tour)
    assert all(a["tour_seconds"] < b["tour_seconds"] for a, b in itertools.pairwise(tour))

    total = tour[-1]["tour_seconds"]
    expect(tab.page.locator("#tour-info")).to_have_text(
        f"tour: {len(tour)} views, predicted robot time to done {total:.1f} s (moves)", timeout=60_000
    )
    names = {f"/tour/{k}/frustum" for k in range(1, len(tour) + 1)} | {"/tour/path", "/tour/1/label"}
    tab.wait(lambda: names <= session_nodes(tab.messages()))
    labels = [
        m["props"]["text"]
        for m in tab.messages()
        if m.get("type") == "LabelMessage" and m.get("name") == "/tour/1/label"
    ]
    assert labels[0] == f"1 · {ring[0]['tour_seconds']:.1f} s" and labels[-1] == f"1 · {tour[0]['tour_seconds']:.1f} s"
    expect(tab.page.locator("[data-testid=move-s]").first).not_to_have_text("–")
