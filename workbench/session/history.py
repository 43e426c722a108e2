"""A live session's timeline: its journal replayed in its worker once, the steps cached until the journal grows.

:meth:`History.step` is what a tab's timeline asks (the session after view ``j``). The steps are built by
:func:`workbench.journal.timeline.timeline_of` from the journal on disk, in the session's worker when it has one
(the same planning cell its plans had; a job like a plan, so a plan of the session waits for it) and else here
in a replay cell of the journal's frames (as ``nbv replay``). The session's lock, state, planner, cell and worker
surface are never touched: looking back changes nothing. The cache holds the steps of one journal length; a new
event (a plan, a view, a discard) makes the next look rebuild them.
"""

from __future__ import annotations

import os
import threading

from workbench.errors import Conflict, Interrupted, Invalid, NotFound
from workbench.journal.rebuild import replay_cell
from workbench.journal.store import JOURNAL_FILE, Journal, read_journal
from workbench.journal.timeline import TimelineStep, timeline_of
from workbench.session.loop import ScanLoop
from workbench.workers.client import JobKilled


class History:
    """The timeline of one session (thread-safe; one build at a time)."""

    def __init__(self, session: ScanLoop) -> None:
        self.session = session
        self._lock = threading.Lock()
        self._key: int | None = None
        """The journal file's size when the steps were built (it only grows: a torn line is cut off again)."""
        self._steps: list[TimelineStep] = []
        self.builds = 0
        """How many times the steps were rebuilt (a cached look rebuilds nothing)."""

    def steps(self) -> list[TimelineStep]:
        """Every step of the session's journal as it is now. Conflict without a journal; Invalid when it cannot
        be replayed; Gone when the session was deleted meanwhile, Interrupted when the
        rebuild was cut off otherwise."""
        s = self.session
        writer = s.journal
        if writer is None:
            raise Conflict(f"session {s.id}: no journal, so no timeline")
        with self._lock:
            try:  # a cached look reads no journal
                key: int | None = os.stat(writer.directory / JOURNAL_FILE).st_size
            except OSError:
                key = None  # read_journal says what is wrong
            if key is not None and key == self._key:
                return self._steps
            journal = read_journal(writer.directory)
            try:
                steps = self._build(journal)
            except JobKilled as exc:  # a valid read cut off (deleted, shutdown): never the request's fault
                if s.deleted:
                    raise s.gone() from None
                raise Interrupted(f"session {s.id}: its timeline rebuild was cut off ({exc}); ask again") from None
            except (ValueError, KeyError, TypeError) as exc:
                raise Invalid(f"session {s.id}: cannot rebuild its timeline from the journal: {exc}") from None
            self._key, self._steps = key, steps
            self.builds += 1
            return steps

    def step(self, view: int) -> TimelineStep:
        """The session after view ``view`` (1-based). NotFound for a view it has not taken."""
        steps = self.steps()
        if not 1 <= view <= len(steps):
            raise NotFound(f"session {self.session.id}: no view {view} in its timeline (views 1 to {len(steps)})")
        return steps[view - 1]

    def _build(self, journal: Journal) -> list[TimelineStep]:
        s = self.session
        if not any(e.get("frame") for e in journal.of_kind("capture")):
            return []  # no view yet: an empty timeline (a replay cell has no frame to play back)
        worker = s.planning_worker()
        if worker is None:
            return timeline_of(journal, replay_cell(journal))
        # coverage comes from the journal's capture events: the replay need not score it again
        return worker.timeline(journal, s.cell.config, s.cell.joint_positions(), s.cell.angle, None)
