"""Auto mode and scripted steps: plan and take the planner's choice, again and again, without a person.

:class:`AutoRunner` belongs to one session. ``step(count)`` runs in the caller's thread; ``start(count)``
runs in a background thread that :meth:`stop` ends after the current action. The first fault ends either
(the session is then in state error). It drives the same steps as a person's approval
(:meth:`ScanLoop.make_plan <workbench.session.loop.ScanLoop.make_plan>`, :meth:`ScanLoop.take_view
<workbench.session.loop.ScanLoop.take_view>`) inside one claim of the session (state ``auto``), so every decision
is journaled and published exactly as a person's would be.
"""

from __future__ import annotations

import contextlib
import threading
from collections.abc import Callable
from typing import Any

from workbench.errors import Conflict
from workbench.session.loop import ScanLoop
from workbench.session.states import TRANSITIONS, Action, State
from workbench.session.values import Decision, DecisionKind, SessionEvent
from workbench.workers.client import JobKilled


class AutoRunner:
    """Runs a session's planner-chosen steps; the session's ``auto_remaining`` counts the steps still to go."""

    def __init__(self, session: ScanLoop) -> None:
        self.session = session
        self._stop = threading.Event()
        self._thread: threading.Thread | None = None

    @property
    def remaining(self) -> int:
        return self.session.auto_remaining

    def _check(self, action: Action) -> Callable[[], None]:
        def check() -> None:
            s = self.session
            s.no_frame_yet()
            refusal = s.cell.auto_refusal()
            if refusal is not None:
                raise Conflict(f"session {s.id}: {TRANSITIONS[action].label} refused: {refusal}")

        return check

    def _begin(self, count: int) -> None:
        self._stop.clear()
        self.session.set_auto_remaining(count)

    def step(self, count: int = 1) -> list[dict[str, Any]]:
        """Plan and take the planner's choice ``count`` times (scripting); stops early when the scan ends."""
        with self.session.enter(Action.STEP, lambda: self._begin(count), self._check(Action.STEP)):
            return self._run(count, DecisionKind.STEP)

    def start(self, count: int) -> None:
        """Run ``count`` steps in a background thread (the claim is made here; the thread settles it)."""
        s = self.session

        def begin() -> None:
            self._begin(count)
            s.emit("auto_start", count=count)

        claim = contextlib.ExitStack()
        claim.enter_context(s.enter(Action.AUTO, begin, self._check(Action.AUTO)))
        thread = threading.Thread(target=self._main, args=(count, claim), name=f"auto-{s.id}", daemon=True)
        self._thread = thread
        try:
            thread.start()
        except BaseException:
            claim.close()
            raise

    def _main(self, count: int, claim: contextlib.ExitStack) -> None:
        with contextlib.suppress(Exception), claim:  # a fault is the error state already; the thread just ends
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
        with s.lock:
            running = s.state == State.AUTO
            if running:
                self._stop.set()
                s.emit("auto_stop")
        if running and s.worker is not None:
            s.worker.cancel("stopped by the operator", kinds=("plan", "integrate"))  # not another tab's read
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
                    entry = s.make_plan(stopping=self._stop.is_set)
                except JobKilled:
                    if self._stop.is_set():
                        break  # Stop killed the plan at once
                    raise
                s.notify(SessionEvent.PLANNED)
                best = entry.plan.best_index
                if best is None or self._stop.is_set():
                    break
                decision = Decision(kind, entry.plan.candidates[best].T_world_camera, entry.plan_id, best, best)
                with s.lock:
                    s.take_decision(decision, entry)
                records.append(s.take_view(decision, entry))
                s.set_auto_remaining(s.auto_remaining - 1)
        finally:
            s.set_auto_remaining(0)
            self._thread = None
        return records
