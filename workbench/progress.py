"""Progress of a long operation (create on a big mesh, a plan, a rebuild) as a page shows it.

:class:`Tracker` holds the running operation of one owner (a session, or one create) and tells its ``sink``
about it: at each new stage, when items are done (at most every ``interval`` seconds within a stage), and
with None when it ends. The planner reports its plan's stages itself (``planner.progress.PlanProgress``); a
create names its stages here (:data:`CREATE_STAGES`).
"""

from __future__ import annotations

import threading
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass, replace
from typing import Any

from planner.progress import PlanProgress, Stages

CREATE_STAGES = (
    "checking the file",
    "reading the mesh",
    "checking the mesh",
    "sampling its surface",
    "building the cell",
    "starting the session",
)
"""The stages of a create on a model file, in order (a built-in object skips the first three)."""

INTERVAL = 0.1
"""Seconds between two reports within one stage."""


class Throttle:
    """Whether a report is worth sending: a new stage, a stage's end, or ``interval`` s since the last one sent
    (a reachability stage reports every candidate; a page needs ten reports a second at most)."""

    def __init__(self, interval: float = INTERVAL) -> None:
        self.interval = interval
        self._stage: str | None = None
        self._sent = 0.0

    def __call__(self, stage: str, done: int, total: int) -> bool:
        now = time.monotonic()
        new_stage, self._stage = self._stage != stage, stage
        if new_stage or done >= total > 0 or now - self._sent >= self.interval:
            self._sent = now
            return True
        return False


@dataclass(frozen=True)
class Progress:
    """Stage ``step`` of ``steps`` (1-based) of ``operation``, ``done`` of ``total`` items of it; ``started``
    is ``time.monotonic()`` at the operation's start; ``stoppable``: the page may offer Stop (or Cancel)."""

    operation: str
    stage: str
    step: int
    steps: int
    done: int
    total: int
    started: float
    stoppable: bool

    @property
    def fraction(self) -> float:
        """0..1 of the operation, each stage counting the same."""
        return PlanProgress(self.stage, self.step, self.steps, self.done, self.total).fraction

    def to_json(self) -> dict[str, Any]:
        """``{"operation", "stage", "step", "steps", "done", "total", "percent", "elapsed", "stoppable"}``."""
        return {
            "operation": self.operation,
            "stage": self.stage,
            "step": self.step,
            "steps": self.steps,
            "done": self.done,
            "total": self.total,
            "percent": round(100.0 * self.fraction, 1),
            "elapsed": round(time.monotonic() - self.started, 2),
            "stoppable": self.stoppable,
        }


class Tracker:
    """The running operation of one owner; ``sink(progress or None)`` hears of each report and of the end.

    Thread-safe: a plan reports from the thread waiting on its worker, a page reads :attr:`current` from another.
    """

    def __init__(self, sink: Callable[[Progress | None], None], interval: float = INTERVAL) -> None:
        self.sink = sink
        self.interval = interval
        self._lock = threading.Lock()
        self._current: Progress | None = None
        self._stages = Stages([], self.plan)  # numbers the stages named by :meth:`stage`
        self._throttle = Throttle(interval)

    @property
    def current(self) -> Progress | None:
        return self._current

    def begin(self, operation: str, stages: Sequence[str] = (), stoppable: bool = False) -> None:
        """A new operation (any running one is replaced); ``stages`` names its stages in order, if known."""
        with self._lock:
            self._stages = Stages(stages, self.plan)
            first = stages[0] if stages else "starting"
            self._current = Progress(operation, first, 1, max(1, len(stages)), 0, 0, time.monotonic(), stoppable)
            self._throttle = Throttle(self.interval)
            self._throttle(first, 0, 0)
            current = self._current
        self.sink(current)

    def stage(self, name: str, done: int = 0, total: int = 0) -> None:
        """The operation is at stage ``name`` (added after the named ones if unnamed), ``done`` of ``total``."""
        self._stages(name, done, total)

    def plan(self, p: PlanProgress) -> None:
        """A report with its stage numbered (by the planner, or by :meth:`stage`)."""
        with self._lock:
            if self._current is None:
                return
            send = self._report(
                replace(self._current, stage=p.stage, step=p.step, steps=p.steps, done=p.done, total=p.total)
            )
        if send is not None:
            self.sink(send)

    def _report(self, new: Progress) -> Progress | None:
        """Keep ``new``; it, when it is to be sent (a new stage, a stage's end, or ``interval`` since the last)."""
        self._current = new
        return new if self._throttle(new.stage, new.done, new.total) else None

    def end(self) -> None:
        """The operation ended (done, failed or stopped)."""
        with self._lock:
            if self._current is None:
                return
            self._current = None
        self.sink(None)
