"""Journaled sessions of an earlier server process, not loaded: what the session list shows of each
(``interrupted``, ``damaged``, or asleep), derived from the journal's events without reading a frame."""

from __future__ import annotations

import contextlib
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from workbench.journal.store import read_journal
from workbench.session.record import SessionRecord
from workbench.session.states import Listed
from workbench.session.summaries import session_status

__all__ = ["DormantSession", "read_dormant", "unreadable"]


@dataclass
class DormantSession:
    """A journaled session of an earlier server process (not loaded): what the session list shows of it.

    ``damage`` (a line of the journal is not an event) lists it as ``damaged`` with the reason; resume then
    recovers everything before the damage and says what was dropped."""

    id: str
    directory: Path
    record: SessionRecord
    """Derived from the journal's events (no frame is read)."""
    stopped: float
    planner: str = "projection"
    """The header's planner (journals without one: projection)."""
    damage: str | None = None
    asleep: bool = False
    """Put to sleep by this server (idle, or to make room): any request for it wakes it (resumes it)."""

    def status(self) -> dict[str, Any]:
        if self.asleep:
            state = Listed.INTERRUPTED
            error = "asleep (idle; its memory was freed): the next request for it wakes it from its journal"
        elif self.damage is not None:
            state = Listed.DAMAGED
            error = f"damaged journal: {self.damage}; a resume of {self.id} recovers what comes before the damage"
        else:
            state = Listed.INTERRUPTED
            error = f"the server stopped during this session; resume {self.id} to continue it"
        return session_status(self.record, state=state, planner=self.planner, source="journal", error=error)


def read_dormant(directory: Path) -> DormantSession | None:
    """The dormant session of a journal folder (None when deleted). ValueError when not even the header reads."""
    journal = read_journal(directory)
    if journal.deleted:
        return None
    record = SessionRecord.from_header(journal.header)
    damage = journal.damage
    applied = 0
    for event in journal.events:
        try:
            record.apply(event)
        except (KeyError, TypeError, ValueError) as exc:  # an event of the right shape with wrong contents
            damage = f"event {event.get('seq')} ({event.get('kind')}) cannot be read: {exc!r}"
            break
        applied += 1
    if damage is not None and journal.damage is not None:
        damage = f"{damage}; {journal.dropped_lines} line(s) from there on are not read"
    stopped = journal.events[applied - 1]["time"] if applied else journal.header["time"]
    planner = str(journal.header.get("planner", "projection"))
    return DormantSession(journal.session_id, directory, record, float(stopped), planner, damage)


def unreadable(directory: Path, reason: str) -> DormantSession:
    """A journal whose header cannot be read: listed as damaged, so it does not vanish."""
    header = {"id": directory.name, "model": {"name": "?"}, "config": {}, "seed": 0, "time": 0.0}
    with contextlib.suppress(OSError):
        header["time"] = (directory / "journal.jsonl").stat().st_mtime
    record = SessionRecord.from_header(header)
    return DormantSession(directory.name, directory, record, float(header["time"]), damage=f"unreadable: {reason}")
