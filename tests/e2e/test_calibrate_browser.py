"""Calibrate mode in the page (real Chromium, live server, the simulated UR5 cell with the 'poor' calibration
model): open Calibrate, start a calibration, preview a pose (the ghost arm is drawn at it in the calibration's own
3D view), approve poses one by one and then all, and read each capture's residual and the estimate with its
uncertainty and its error against the simulated truth."""

from __future__ import annotations

import httpx
import pytest
from playwright.sync_api import BrowserContext, expect

from tests.e2e.test_workbench_browser import Tab
from tests.servers import LiveServer

pytestmark = pytest.mark.e2e  # tests/conftest.py: the long groups are handed out first


def test_calibrate_mode_previews_approves_and_shows_residuals_and_the_estimate(
    live_server: LiveServer, browser_context: BrowserContext
) -> None:
    tab = Tab(browser_context, f"{live_server.url}/")
    page = tab.page
    page.get_by_test_id("calibrate-open").click()
    expect(page.get_by_test_id("calibrate")).to_be_visible()
    page.fill("#cal-angles", "0,120,-120")
    page.fill("#cal-views", "3")
    page.get_by_test_id("cal-start").click()
    rows = page.locator("#cal-poses tbody tr")
    expect(rows).to_have_count(9, timeout=30_000)
    assert "calibrate=cal-" in page.url
    cid = page.url.split("calibrate=")[1]

    # the calibration's own 3D view: the target, the pose cameras and the arm (its link meshes)
    def names() -> set[str]:
        return {str(m.get("name", "")) for m in tab.messages()}

    tab.wait(lambda: "/calibration/target" in names() and "/calibration/poses/8" in names(), timeout_ms=20_000)
    tab.wait(lambda: sum(n.startswith("/robot/arm/") for n in names()) >= 7, timeout_ms=20_000)

    # preview pose 0: the ghost at the pose and the camera's path; nothing moved
    rows.nth(0).locator("button[data-act=preview]").click()
    expect(rows.nth(0)).to_have_class("selected")
    tab.wait(lambda: "/robot/path" in names() and sum(n.startswith("/robot/ghost/") for n in names()) >= 7)
    assert rows.nth(0).get_attribute("data-status") == "pending"

    # approve one pose, skip one, then approve all the rest
    rows.nth(0).locator("button[data-act=approve]").click()
    expect(rows.nth(0)).to_have_attribute("data-status", "captured")
    expect(page.get_by_test_id("cal-estimate")).to_contain_text("need at least 6")
    rows.nth(1).locator("button[data-act=skip]").click()
    expect(rows.nth(1)).to_have_attribute("data-status", "skipped")
    page.get_by_test_id("cal-approve-all").click()
    expect(page.locator("#cal-poses tbody tr[data-status=captured]")).to_have_count(8, timeout=25_000)

    # residuals per capture and the estimate with its uncertainty and its check against the truth
    residuals = [
        t.strip()
        for t in page.locator("#cal-poses tbody tr[data-status=captured] [data-testid=residual]").all_inner_texts()
    ]
    assert len(residuals) == 8 and all(0.0 < float(r) < 3.0 for r in residuals), residuals
    estimate = page.get_by_test_id("cal-estimate")
    expect(estimate).to_contain_text("hand-eye translation")
    expect(estimate).to_contain_text("±")
    expect(estimate).to_contain_text("error vs truth")
    status = httpx.get(f"{live_server.url}/api/calibrations/{cid}").json()
    assert status["counts"] == {"pending": 0, "captured": 8, "skipped": 1}
    assert status["truth"]["hand_eye_error_mm"] < status["truth"]["nominal_error"]["hand_eye_mm"]
    assert f"{status['estimate']['hand_eye_std_mm']:.3f}" in estimate.inner_text()
    # a simulated cell has no file to write
    expect(page.get_by_test_id("cal-write")).to_be_disabled()
