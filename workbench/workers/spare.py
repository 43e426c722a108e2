"""``SpareCore``: lets speculative work (a new worker's warm-up) run only while it has a core to itself.

A worker's warm-up (workbench/workers/child.py ``_Worker.warm``) fills the reachability cache of a first plan that
may never come: a session created and then only listed, put to sleep or deleted paid its 0.1-0.6 s of CPU all
the same, taken from the captures and plans of the sessions in use when the machine was busy. The warm-up asks
:meth:`SpareCore.go` between its steps (a candidate's reachability, about a millisecond of CPU each); ``go``
measures the share of a core the work got over the last :data:`WINDOW` seconds (the thread's CPU time against the
wall time) and, when it is below :data:`SHARE` (other work wants the cores), pauses before the next step: for
:data:`PAUSES` seconds in turn, one window of work between two pauses to measure again, then it gives up. A pause
ends at once when a job arrives (``wait`` returns True), and so does the warm-up.

Nothing changes priority (raising a lowered priority back needs a privilege, and a warm-up at nice 19 crawled on
a busy machine: a capture that waited for it took 21-34 s with two busy loops on the two cores, measured); the
steps run at full speed, one window at a time, so a job that arrives waits for one step at most, as before.
"""

from __future__ import annotations

import time
from collections.abc import Callable, Sequence

SHARE = 0.8
"""The share of a core the work must get to go on: alone on a core it gets about 1; beside one other busy thread
on the same core about 0.5."""
WINDOW = 0.02
"""Seconds of work between two measurements."""
PAUSES = (0.05, 0.1, 0.2, 0.4, 0.8, 1.6, 3.2)
"""The pauses, seconds, while the cores stay busy (6.35 s in all, with a window of work between two); a window
that got its core back starts over from the first."""


class SpareCore:
    """Asked between the steps of speculative work: go on, pause, or stop."""

    def __init__(
        self,
        hurry: Callable[[], bool],
        wait: Callable[[float], bool],
        share: float = SHARE,
        window: float = WINDOW,
        pauses: Sequence[float] = PAUSES,
        clock: Callable[[], float] = time.perf_counter,
        cpu: Callable[[], float] = time.thread_time,
    ) -> None:
        """``hurry()``: True once a job waits; ``wait(seconds)``: sleep up to ``seconds``, True when a job arrived
        meanwhile; ``clock`` / ``cpu``: wall time and this thread's CPU time, seconds."""
        self.hurry, self.wait, self.share, self.window, self.pauses = hurry, wait, share, window, tuple(pauses)
        self.clock, self.cpu = clock, cpu
        self.paused = 0
        """Pauses in a row so far (0 once a window got its core)."""
        self.paused_seconds = 0.0
        """Seconds of the pauses begun (one that a job cut short counts whole)."""
        self._t0, self._c0 = clock(), cpu()

    def go(self) -> bool:
        """True: do the next step (after a pause when the last window got less than ``share`` of a core).
        False: stop, because a job waits or the cores stayed busy through every pause."""
        if self.hurry():
            return False
        wall = self.clock() - self._t0
        if wall < self.window:
            return True
        if (self.cpu() - self._c0) / wall >= self.share:
            self.paused = 0
        else:
            if self.paused >= len(self.pauses):
                return False
            seconds = self.pauses[self.paused]
            self.paused += 1
            self.paused_seconds += seconds
            if self.wait(seconds):
                return False
        self._t0, self._c0 = self.clock(), self.cpu()
        return True
