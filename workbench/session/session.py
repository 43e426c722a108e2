"""One supervised scan: the planner, the cell and the state machine a person drives.

:class:`Session` is what the registry, the web layer and the scene use: the scan loop's actions
(:class:`~workbench.session.loop.ScanLoop`: capture, plan, select, override, approve, retry, configure) on the
session's core (:class:`~workbench.session.core.SessionCore`: the fields, the lock, the one writer of the state),
with auto mode (workbench/session/auto.py), the timeline (history.py), a refit, a discard, stop, resume and close.
The states and the transition table are in workbench/session/states.py.

``done`` means the planner's termination rule fired; a person may still plan and approve more views from
there. ``error`` keeps the map (a failed step never reaches ``Planner.integrate``) and restores the plan
whose approval failed as pending, so approving it again, ``retry`` (re-do the failed step exactly) or a new
plan all leave it.
"""

from __future__ import annotations

from typing import Any

from planner.ellipsoids import fit_at_t
from workbench.errors import Conflict, Interrupted, Invalid, StorageFault
from workbench.journal.discard import last_capture
from workbench.journal.rebuild import REPLAY_STAGE, Rebuilt
from workbench.journal.store import JournalWriter, read_journal
from workbench.session.auto import AutoRunner
from workbench.session.fit import KINDS, Refit
from workbench.session.history import History
from workbench.session.loop import ScanLoop
from workbench.session.states import BUSY, Action
from workbench.session.values import SessionEvent
from workbench.workers.client import JobKilled

STOP_WAIT = 5.0
"""How long ``stop`` waits for a halted move to end (the session then shows its error state), seconds."""


class Session(ScanLoop):
    """A supervised scan of one object. Every state change of a session goes through here."""

    auto: AutoRunner
    """Step and auto mode (``auto.step(n)``, ``auto.start(n)``, ``auto.stop()``)."""
    history: History
    """The session as it was after each view, rebuilt from its journal (``history.step(j)``; changes nothing)."""

    def _compose(self) -> None:
        self.auto = AutoRunner(self)
        self.history = History(self)

    # ------------------------------------------------------------------ inspect and undo

    def refit(self, kind: str, t: int) -> Refit:
        """``kind``'s voxels of the current plan fitted at ``t`` components, in the worker; changes nothing
        (workbench/session/fit.py).

        Invalid for an unknown kind or a T outside [1, min(voxels, max(t_max, the plan's T))]; Conflict without a
        plan, or when the worker job is killed (budget, Stop, DELETE)."""
        if kind not in KINDS:
            raise Invalid(f"kind: must be one of {', '.join(KINDS)}, got {kind!r}")
        entry = self.plan_for()
        plan = entry.plan
        points = plan.voxels.occupied if kind == "occupied" else plan.voxels.frontier
        chosen = max((f.t_chosen for f in plan.fits if f.kind == kind), default=0)
        t_hi = min(len(points), max(self.config.cluster.t_max, chosen))
        if isinstance(t, bool) or not isinstance(t, int) or not 1 <= t <= t_hi:
            raise Invalid(f"t: must be an integer in [1, {t_hi}] for the {len(points)} {kind} voxels, got {t!r}")
        payload = (points, self.config.cluster, plan.voxels.resolution, kind, t)
        try:
            if self.worker is None:
                ellipsoids, fit = fit_at_t(*payload)
            else:
                ellipsoids, fit = self.worker.call("fit", payload, self.plan_budget, f"the {kind} fit at T={t}")
        except JobKilled as exc:
            raise Conflict(f"session {self.id}: {exc}") from None
        return Refit(entry.plan_id, kind, t, tuple(ellipsoids), fit)  # type: ignore[arg-type]

    def discard_last_view(self) -> dict[str, Any]:
        """Undo the last capture: rebuild the session from its journal without that frame (a bad capture undone);
        returns ``{"discarded": iteration, "mismatches": [...]}``.

        The ``discard`` event is journaled first, then the session is rebuilt by replaying its journal (which now
        leaves that capture out, workbench/journal/discard.py) and takes the rebuilt state over: map, cloud, views,
        record. The plan whose approval took the discarded view is pending again (approve another candidate of it,
        or plan again). The frame file stays on disk. The session is in state ``discarding`` meanwhile.
        Conflict without a journal, without a view, or while busy; Invalid when the journal cannot be replayed
        (the session is then back in the state it was in, its map as it was before the call).
        """
        journal = self.journal
        if journal is None:
            raise Conflict(f"session {self.id}: no journal to rebuild from; cannot discard a view")

        def prepare(journal: JournalWriter = journal) -> dict[str, Any]:
            last = last_capture(read_journal(journal.directory).events)
            if last is None:
                raise Conflict(f"session {self.id}: no view to discard")
            try:
                journal.append("discard", capture_seq=last["seq"], iteration=last["iteration"])
            except OSError as exc:  # a full disk: nothing discarded, the session as it was
                raise StorageFault(f"session {self.id}: cannot discard the last view: {exc.strerror or exc}") from None
            return last

        with self.enter(Action.DISCARD, prepare) as claim:
            last = claim.value
            assert last is not None
            self.progress.begin("discard", [REPLAY_STAGE])
            try:
                rebuilt = self.replay(read_journal(journal.directory), self.progress.stage)
            except JobKilled as exc:  # cut off (deleted, Stop, shutdown): the request was valid
                if self.deleted:
                    raise self.gone() from None
                raise Interrupted(f"session {self.id}: the rebuild without the last view was cut off ({exc})") from None
            except (ValueError, KeyError, TypeError) as exc:
                raise Invalid(f"session {self.id}: cannot rebuild without the last view: {exc}") from None
            finally:
                self.progress.end()
            self.take_over(rebuilt)
            claim.news.append(SessionEvent.CAPTURED)
        return {"discarded": int(last["iteration"]), "mismatches": rebuilt.mismatches}

    # ------------------------------------------------------------------ stop, resume and close

    def stop(self) -> None:
        """Stop what runs: a plan (killed at once in its worker; the session goes back to its state before it, the
        plan request answers 409), auto mode (after the current action; a plan of it is killed at once), and a
        running move of a cell that can halt its devices (hardware): the arm and the turntable stop at once, the
        session goes to its error state (waited for up to ``STOP_WAIT`` s)."""
        self.stop_plan()
        self.auto.stop()
        if self.cell.halt() is not None:
            self.wait_until(lambda: self.state not in BUSY or not self.cell.halting, STOP_WAIT)

    def restore(self, rebuilt: Rebuilt) -> None:
        """Take over a session rebuilt from its journal (called once, before the session is shared)."""
        with self.enter(Action.RESUME):
            self.take_over(rebuilt)

    def close(self, timeout: float = 30.0) -> None:
        """Kill a running job and the worker, stop auto mode and wait for it (on delete and at shutdown); release
        hanging devices; close the journal and the devices."""
        if self.worker is not None:
            self.worker.close()
        self.auto.stop_and_join(timeout, release=self.injector.release if self.injector is not None else None)
        self.listeners.clear()
        if self.journal is not None:
            self.journal.close()
        self.cell.close()
