"""Discard the last view of a session: rebuild it from its journal without that frame (a bad capture undone).

The ``discard`` event is journaled first, then the session is rebuilt by replaying its journal (which now
leaves that capture out, workbench/journal/discard.py) and takes the rebuilt state over: map, cloud, views,
record. The plan whose approval took the discarded view is pending again (approve another candidate of it,
or plan again). The frame file stays on disk. The session is claimed busy (``capturing``) meanwhile.
"""

from __future__ import annotations

from typing import TYPE_CHECKING, Any

from workbench.engine import JobKilled
from workbench.errors import Conflict, Invalid, StorageFault
from workbench.journal.discard import last_capture
from workbench.journal.rebuild import REPLAY_STAGE
from workbench.journal.store import read_journal
from workbench.states import BUSY, SessionEvent, State

if TYPE_CHECKING:
    from workbench.session import Session


def discard_last_view(wb: Session) -> dict[str, Any]:
    """Undo the last capture of ``wb``; returns ``{"discarded": iteration, "mismatches": [...]}``.

    Conflict without a journal, without a view, or while busy; Invalid when the journal cannot be replayed
    (the session is then left in state error with its map as it was before the call).
    """
    journal = wb.journal
    if journal is None:
        raise Conflict(f"session {wb.id}: no journal to rebuild from; cannot discard a view")
    with wb._lock:
        if wb.state in BUSY:
            raise Conflict(f"session {wb.id} is busy ({wb.state}); discard refused")
        last = last_capture(read_journal(journal.directory).events)
        if last is None:
            raise Conflict(f"session {wb.id}: no view to discard")
        before = wb.claim(frozenset(State) - BUSY - {State.INTERRUPTED}, State.CAPTURING, "discard")
        try:
            journal.append("discard", capture_seq=last["seq"], iteration=last["iteration"])
        except OSError as exc:  # a full disk: nothing discarded, the session as it was
            wb._state = before
            raise StorageFault(f"session {wb.id}: cannot discard the last view: {exc.strerror or exc}") from None
    wb.notify(SessionEvent.STATE)
    wb.progress.begin("discard", [REPLAY_STAGE])
    try:
        rebuilt = wb.replay(read_journal(journal.directory), wb.progress.stage)
    except (ValueError, KeyError, TypeError, JobKilled) as exc:
        with wb._lock:
            wb._state = before
        wb.notify(SessionEvent.STATE)
        if wb.deleted:
            raise wb.gone() from None
        raise Invalid(f"session {wb.id}: cannot rebuild without the last view: {exc}") from None
    finally:
        wb.progress.end()
    with wb._lock:
        wb._error = None
        wb._failed = None
        wb._custom = None
    wb.restore(rebuilt)
    wb.notify(SessionEvent.CAPTURED)
    return {"discarded": int(last["iteration"]), "mismatches": rebuilt.mismatches}
