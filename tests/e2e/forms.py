"""The create form filled for a small, fast session (the browser tests share it)."""

from __future__ import annotations

from typing import Any

SMALL_FORM = (("p-resolution", "0.02"), ("p-count", "60"), ("p-parallels", "4"), ("p-tmin", "2"), ("p-tmax", "6"))
"""(field id, value) of the create form: a coarse map, few candidates, a narrow T range."""


def open_advanced(page: Any) -> None:
    """Open the create form's "Advanced" part (the sensor, the calibration and the planner's numbers)."""
    if not page.locator("#advanced").evaluate("(d) => d.open"):
        page.locator("#advanced > summary").click()


def fill_small_form(page: Any) -> None:
    """Fill the page's create form with :data:`SMALL_FORM` (its "Advanced" part opened)."""
    open_advanced(page)
    for field, value in SMALL_FORM:
        page.fill(f"#{field}", value)
