"""The page's sensor and calibration selects in real Chromium against a live server: a session created
from the form with the RealSense D435 model scans with it, and the coverage chart shows its precision and F."""

from __future__ import annotations

import re

import httpx
import pytest
from playwright.sync_api import BrowserContext, expect

from devices.sensors.presets import SENSORS
from tests.e2e.forms import fill_small_form, open_advanced
from tests.servers import LiveServer

pytestmark = pytest.mark.e2e  # tests/conftest.py: the long groups are handed out first


def test_a_d435_session_from_the_form_charts_precision(
    live_server: LiveServer, browser_context: BrowserContext
) -> None:
    page = browser_context.new_page()
    page.goto(f"{live_server.url}/")
    options = page.locator("#sensor option")
    expect(options).to_have_count(len(SENSORS) + 1)  # the server's default, then every model
    page.select_option("#model", "l-block")
    open_advanced(page)  # the sensor and calibration models are advanced choices
    page.select_option("#sensor", "realsense-d435")
    page.select_option("#calibration", "typical")
    fill_small_form(page)
    page.click("#create")
    page.wait_for_url(re.compile(r"\?session=[0-9a-f]{8}"))
    sid = re.search(r"session=([0-9a-f]{8})", page.url).group(1)  # type: ignore[union-attr]
    expect(page.locator("#state")).to_have_text("new", timeout=60_000)
    page.click("#capture")
    expect(page.locator("#state")).to_have_text("ready", timeout=60_000)
    page.click("#plan")
    expect(page.locator("#state")).to_have_text("planned", timeout=60_000)
    page.click("#approve")
    expect(page.locator("#iteration")).to_have_text("2", timeout=60_000)

    chart = page.locator("#chart-coverage")
    expect(chart.locator("text", has_text="precision@5mm")).to_have_count(1, timeout=30_000)
    expect(chart.locator("text", has_text="F@5mm")).to_have_count(1)
    precision_dots = chart.locator("circle[fill='#2e63d8']")  # one dot per view of the precision series
    expect(precision_dots).to_have_count(2)

    api = httpx.Client(base_url=live_server.url, timeout=60)
    views = api.get(f"/api/sessions/{sid}").json()["views"]
    assert len(views) == 2 and all(0.5 < v["precision_5mm"] <= 1.0 for v in views)
    shown = precision_dots.first.locator("title").text_content() or ""
    assert shown.startswith("1, ") and abs(float(shown.split(", ")[1]) - 100 * views[0]["precision_5mm"]) < 0.06
    export = api.get(f"/api/sessions/{sid}/export").json()
    assert export["config"]["noise"]["depth_z2"] > 0  # the planner config followed the D435 picked in the form
