"""HTTP statuses of the workbench's domain errors (workbench/errors.py): the one place types meet codes."""

from __future__ import annotations

from workbench import (
    AtCapacity,
    Conflict,
    DeviceFault,
    Gone,
    Interrupted,
    Invalid,
    NotFound,
    StorageFault,
    TooLarge,
    Unreachable,
    WorkbenchError,
)

STATUS: dict[type[WorkbenchError], int] = {
    NotFound: 404,
    Conflict: 409,
    TooLarge: 413,
    Unreachable: 422,
    Invalid: 422,
    StorageFault: 503,
    DeviceFault: 503,
    AtCapacity: 503,
    Interrupted: 503,
    Gone: 410,
}
"""The status of each error type (the most derived type listed wins)."""


def status_of(error: WorkbenchError) -> int:
    """The HTTP status of ``error``: its type's, else its nearest listed base's, else 400."""
    for cls in type(error).__mro__:
        if cls in STATUS:
            return STATUS[cls]
    return 400
