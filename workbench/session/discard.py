"""Discard the last view of a session: rebuild it from its journal without that frame (a bad capture undone).

The ``discard`` event is journaled first, then the session is rebuilt by replaying its journal (which now
leaves that capture out, workbench/journal/discard.py) and takes the rebuilt state over: map, cloud, views,
record. The plan whose approval took the discarded view is pending again (approve another candidate of it,
or plan again). The frame file stays on disk. The session is in state ``discarding`` meanwhile.
"""

from __future__ import annotations

from typing import Any

from workbench.errors import Conflict, Interrupted, Invalid, StorageFault
from workbench.journal.discard import last_capture
from workbench.journal.rebuild import REPLAY_STAGE
from workbench.journal.store import JournalWriter, read_journal
from workbench.session.core import SessionCore
from workbench.session.loop import replay
from workbench.session.states import Action
from workbench.session.values import SessionEvent
from workbench.workers.client import JobKilled


def discard_last_view(s: SessionCore) -> dict[str, Any]:
    """Undo the last capture of ``s``; returns ``{"discarded": iteration, "mismatches": [...]}``.

    Conflict without a journal, without a view, or while busy; Invalid when the journal cannot be replayed
    (the session is then back in the state it was in, its map as it was before the call).
    """
    journal = s.journal
    if journal is None:
        raise Conflict(f"session {s.id}: no journal to rebuild from; cannot discard a view")

    def prepare(journal: JournalWriter = journal) -> dict[str, Any]:
        last = last_capture(read_journal(journal.directory).events)
        if last is None:
            raise Conflict(f"session {s.id}: no view to discard")
        try:
            journal.append("discard", capture_seq=last["seq"], iteration=last["iteration"])
        except OSError as exc:  # a full disk: nothing discarded, the session as it was
            raise StorageFault(f"session {s.id}: cannot discard the last view: {exc.strerror or exc}") from None
        return last

    with s.enter(Action.DISCARD, prepare) as claim:
        last = claim.value
        assert last is not None
        s.progress.begin("discard", [REPLAY_STAGE])
        try:
            rebuilt = replay(s, read_journal(journal.directory), s.progress.stage)
        except JobKilled as exc:  # cut off (deleted, Stop, shutdown): the request was valid
            if s.deleted:
                raise s.gone() from None
            raise Interrupted(f"session {s.id}: the rebuild without the last view was cut off ({exc})") from None
        except (ValueError, KeyError, TypeError) as exc:
            raise Invalid(f"session {s.id}: cannot rebuild without the last view: {exc}") from None
        finally:
            s.progress.end()
        s.take_over(rebuilt)
        claim.news.append(SessionEvent.CAPTURED)
    return {"discarded": int(last["iteration"]), "mismatches": rebuilt.mismatches}
