"""Auto mode and scripted steps: plan and take the planner's choice, again and again, without a person.

:class:`AutoRunner` belongs to one session. ``step(count)`` runs in the caller's thread; ``start(count)``
runs in a background thread that :meth:`stop` ends after the current action. The first fault ends either
(the session is then in state error). It only drives the session's public steps (claim, make_plan,
take_view), so every decision is journaled and published exactly as a person's approval would be.
"""

from __future__ import annotations

import contextlib
import threading
from collections.abc import Callable
from typing import TYPE_CHECKING, Any

from workbench.errors import Conflict
from workbench.session.values import Decision, DecisionKind, SessionEvent, State
from workbench.sources.hardware import auto_refusal
from workbench.workers.pool import JobKilled

if TYPE_CHECKING:
    from workbench.session.session import Session

RUNNABLE = frozenset({State.READY, State.PLANNED, State.DONE})


class AutoRunner:
    """Runs a session's planner-chosen steps; ``remaining`` counts the steps still to go."""

    def __init__(self, session: Session) -> None:
        self.session = session
        self.remaining = 0
        self._stop = threading.Event()
        self._thread: threading.Thread | None = None

    def _claim(self, count: int, action: str) -> None:
        s = self.session
        if s.planner.iteration == 0:
            raise Conflict(f"session {s.id}: no frame yet; capture first")
        refusal = auto_refusal(s.cell)
        if refusal is not None:
            raise Conflict(f"session {s.id}: {action} refused: {refusal}")
        s.claim(RUNNABLE, State.AUTO, action)
        self._stop.clear()
        self.remaining = count

    def step(self, count: int = 1) -> list[dict[str, Any]]:
        """Plan and take the planner's choice ``count`` times (scripting); stops early when the scan ends."""
        with self.session._lock:
            self._claim(count, "step")
        self.session.notify(SessionEvent.STATE)
        return self._run(count, DecisionKind.STEP)

    def start(self, count: int) -> None:
        """Run ``count`` steps in a background thread."""
        s = self.session
        with s._lock:
            self._claim(count, "start auto mode")
            s._emit("auto_start", count=count)
            thread = threading.Thread(target=self._main, args=(count,), name=f"auto-{s.id}", daemon=True)
            self._thread = thread
        s.notify(SessionEvent.STATE)
        thread.start()

    def _main(self, count: int) -> None:
        with contextlib.suppress(Exception):  # already recorded as the error state; the thread just ends
            self._run(count, DecisionKind.AUTO)

    @property
    def stopping(self) -> bool:
        """Stop was asked and the run has not ended yet."""
        return self._stop.is_set()

    def stop(self) -> bool:
        """Stop auto mode: a plan or integration running in the session's worker is killed at once (a killed plan
        just ends auto mode; a killed integration leaves its view step in state error to retry, map unchanged); a
        move or capture in flight ends first. True when auto mode was running."""
        s = self.session
        with s._lock:
            running = s.state == State.AUTO
            if running:
                self._stop.set()
                s._emit("auto_stop")
        if running and s.worker is not None:
            s.worker.cancel("stopped by the operator")
        return running

    def join(self, timeout: float) -> bool:
        """Wait up to ``timeout`` s for the background run to end; True when none is running any more."""
        thread = self._thread
        if thread is not None and thread is not threading.current_thread():
            thread.join(timeout)
            return not thread.is_alive()
        return True

    def stop_and_join(self, timeout: float, release: Callable[[], None] | None = None) -> None:
        """Stop, let hanging devices go (``release``), and wait up to ``timeout`` s for the thread to end."""
        self._stop.set()
        if release is not None:
            release()
        self.join(timeout)

    def _run(self, count: int, kind: DecisionKind) -> list[dict[str, Any]]:
        s = self.session
        records: list[dict[str, Any]] = []
        try:
            for _ in range(count):
                if self._stop.is_set() or s.planner.terminated is not None:
                    break
                try:
                    entry = s.make_plan()
                except JobKilled:
                    if self._stop.is_set():
                        break  # Stop killed the plan at once
                    raise
                s.notify(SessionEvent.PLANNED)
                best = entry.plan.best_index
                if best is None or self._stop.is_set():
                    break
                with s._lock:
                    s.consume(entry)
                    target = entry.plan.candidates[best].T_world_camera
                    decision = Decision(kind, target, entry.plan_id, best, best)
                    s.record_decision(decision)
                records.append(s.take_view(decision, entry))
                with s._lock:
                    self.remaining -= 1
        finally:
            with s._lock:
                if s.state == State.AUTO:
                    s._state = s.settle()
                self.remaining = 0
                self._thread = None
            s.notify(SessionEvent.STATE)
        return records
