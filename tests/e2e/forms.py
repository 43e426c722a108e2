"""The create form filled for a small, fast session (the browser tests share it)."""

from __future__ import annotations

from typing import Any

SMALL_FORM = (("p-resolution", "0.02"), ("p-count", "60"), ("p-parallels", "4"), ("p-tmin", "2"), ("p-tmax", "6"))
"""(field id, value) of the create form: a coarse map, few candidates, a narrow T range."""


def fill_small_form(page: Any) -> None:
    """Fill the page's create form with :data:`SMALL_FORM`."""
    for field, value in SMALL_FORM:
        page.fill(f"#{field}", value)
