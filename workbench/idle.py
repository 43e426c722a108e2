"""Puts idle live sessions to sleep: a daemon thread that asks the registry, every so often, to send the sessions
idle for longer than ``idle_sleep`` seconds back to their journal (workbench/registry.py ``sleep_idle``)."""

from __future__ import annotations

import logging
import threading
from collections.abc import Callable

log = logging.getLogger(__name__)


class IdleSweeper:
    """Calls ``sweep()`` every ``period`` seconds in a daemon thread until :meth:`close`."""

    def __init__(self, sweep: Callable[[], None], period: float) -> None:
        self._sweep = sweep
        self._period = period
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._run, name="idle-sessions", daemon=True)
        self._thread.start()

    def _run(self) -> None:
        while not self._stop.wait(self._period):
            try:
                self._sweep()
            except Exception:  # a failing sweep must not end the sweeping
                log.exception("idle sessions: sweep failed")

    def close(self) -> None:
        self._stop.set()
        self._thread.join(5.0)
