"""Calling a device with a deadline, so a camera that never answers cannot hang a session (or the server).

A Python thread cannot be killed: the call runs in a daemon thread, and when the
deadline passes the caller gets :class:`DeviceTimeoutError` while that thread is
left to finish (or hang) on its own. A real driver should also enforce its own
timeout; this is the workbench's backstop.
"""

from __future__ import annotations

import threading
import time
from collections.abc import Callable
from typing import Any, TypeVar

from devices.protocols import DeviceError

T = TypeVar("T")


class DeviceTimeoutError(DeviceError):
    """A device did not answer within its deadline. ``pending`` is set once the abandoned call has ended."""

    def __init__(self, message: str, pending: threading.Event | None = None) -> None:
        super().__init__(message)
        self.pending = pending


def call_with_timeout(
    fn: Callable[[], T],
    timeout: float | None,
    what: str,
    on_timeout: Callable[[], None] | None = None,
    waited: Callable[[], float] | None = None,
) -> T:
    """``fn()``, or DeviceTimeoutError when it has not returned after ``timeout`` seconds (None or <= 0: no limit).

    Exceptions of ``fn`` are re-raised in the caller. On a timeout ``on_timeout()`` is called first (a driver's
    ``stop()``: a move that timed out must not go on); the error's ``pending`` event tells when the abandoned
    call has really ended, so a retry can wait for it instead of sending a second move.
    ``waited()``: seconds ``fn`` has spent so far waiting its turn for a shared resource (a simulated camera's
    render waiting for a running-job slot of the server, busy with other sessions): they do not count, so only
    the device's own time is limited.
    """
    if timeout is None or timeout <= 0:
        return fn()
    box: dict[str, Any] = {}
    done = threading.Event()

    def run() -> None:
        try:
            box["value"] = fn()
        except BaseException as exc:  # handed to the caller
            box["error"] = exc
        finally:
            done.set()

    thread = threading.Thread(target=run, name=f"device-{what}", daemon=True)
    thread.start()
    start = time.monotonic()
    while not done.is_set():
        left = start + timeout + (waited() if waited is not None else 0.0) - time.monotonic()
        if left <= 0 or done.wait(min(left, 0.5)):
            break
    if not done.is_set():
        stopped = ""
        if on_timeout is not None:
            try:
                on_timeout()
                stopped = "; stopped"
            except Exception as exc:  # the stop failed too: say so, the caller still gets the timeout
                stopped = f"; stop failed: {exc}"
        raise DeviceTimeoutError(f"{what}: no answer within {timeout:g} s (timeout{stopped})", done)
    if "error" in box:
        raise box["error"]
    return box["value"]
