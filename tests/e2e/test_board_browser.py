"""The class board in real Chromium against a live server: the join code and its QR code, a card per seat that
follows its session (state, views, picture), a student's join link that opens the seat's session in the
workbench, Pause all, and a seat's read-only view on the projector."""

from __future__ import annotations

import httpx
import pytest
from playwright.sync_api import BrowserContext, expect

from tests.helpers import SMALL
from tests.servers import LiveServer

pytestmark = pytest.mark.e2e  # tests/conftest.py: the long groups are handed out first


def test_the_board_follows_its_seats_and_a_student_joins(
    live_server: LiveServer, browser_context: BrowserContext
) -> None:
    api = httpx.Client(base_url=live_server.url, timeout=120)
    made = api.post("/api/classes", json={"seats": 2, "model": "l-block", "config": SMALL, "guided": True}).json()
    board = browser_context.new_page()
    board.goto(f"{live_server.url}/board/{made['id']}")
    expect(board.get_by_test_id("join-code")).to_have_text(made["code"])
    expect(board.get_by_test_id("join-url")).to_have_text(f"{live_server.url}/join/{made['code']}")
    assert board.get_by_test_id("join-qr").evaluate("img => img.complete && img.naturalWidth > 100")
    expect(board.get_by_test_id("seat-1-state")).to_have_text("new")
    expect(board.locator(".seat")).to_have_count(2)

    student = browser_context.new_page()  # a student opens the join link: the seat's session, in the workbench
    student.route(lambda url: "/?session=" in url, lambda route: route.fulfill(body="the workbench"))  # not loaded
    student.goto(f"{live_server.url}/join/{made['code']}")
    student.wait_for_url(f"**/?session={made['seats'][0]['session']}&seat=1", timeout=30_000)
    expect(board.get_by_test_id("seat-1")).to_contain_text("joined", timeout=10_000)
    student.close()

    api.post(f"/api/sessions/{made['seats'][0]['session']}/capture").raise_for_status()
    expect(board.get_by_test_id("seat-1-state")).to_have_text("ready", timeout=10_000)
    expect(board.get_by_test_id("seat-1")).to_contain_text("views 1")
    picture = board.get_by_test_id("seat-1").locator("img.pic")
    expect(picture).to_have_count(1)
    board.wait_for_function("() => document.querySelector('[data-seat=\"1\"] img.pic').naturalWidth === 160")

    board.get_by_test_id("pause-all").click()
    expect(board.get_by_test_id("pause-all")).to_have_text("Resume all")
    assert api.get(f"/api/classes/{made['id']}").json()["paused"] is True
    assert api.post(f"/api/sessions/{made['seats'][1]['session']}/capture").status_code == 409

    board.route(lambda url: "ticket" in url, lambda route: route.fulfill(body="the 3D viewer"))  # not loaded
    board.get_by_test_id("seat-1").get_by_role("button", name="Project").click()
    expect(board.get_by_test_id("projector")).to_be_visible()
    assert "ticket" in (board.locator("#projector-view").get_attribute("src") or "")
