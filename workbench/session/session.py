"""One supervised scan: the planner, the cell and the state machine a person drives.

:class:`Session` is the facade the registry, the web layer and the scene use: each of its actions is one call
into workbench/session/loop.py, auto.py or discard.py, built on :class:`~workbench.session.core.SessionCore`
(the fields, the lock, the one writer of the state). The states and the transition table are in
workbench/session/states.py.

``done`` means the planner's termination rule fired; a person may still plan and approve more views from
there. ``error`` keeps the map (a failed step never reaches ``Planner.integrate``) and restores the plan
whose approval failed as pending, so approving it again, ``retry`` (re-do the failed step exactly) or a new
plan all leave it.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

import workbench.session.loop as loop
from planner import Pose
from workbench.journal.rebuild import Rebuilt
from workbench.journal.store import Journal
from workbench.session.auto import AutoRunner
from workbench.session.core import SessionCore
from workbench.session.discard import discard_last_view
from workbench.session.fit import Refit, refit
from workbench.session.history import History
from workbench.session.states import BUSY, Action
from workbench.session.values import CustomPose, PendingPlan

STOP_WAIT = 5.0
"""How long ``stop`` waits for a halted move to end (the session then shows its error state), seconds."""


class Session(SessionCore):
    """A supervised scan of one object. Every state change of a session goes through here."""

    auto: AutoRunner
    """Step and auto mode (``auto.step(n)``, ``auto.start(n)``, ``auto.stop()``)."""
    history: History
    """The session as it was after each view, rebuilt from its journal (``history.step(j)``; changes nothing)."""

    def _compose(self) -> None:
        self.auto = AutoRunner(self)
        self.history = History(self)

    # ------------------------------------------------------------------ the loop

    def capture(self) -> dict[str, Any]:
        """Capture and integrate the first view at the cell's initial pose."""
        return loop.capture(self)

    def retry(self) -> dict[str, Any]:
        """Re-do the step a fault interrupted (the same pose, the same decision). Conflict when there is none."""
        return loop.retry(self)

    def plan(self) -> PendingPlan:
        """Score the candidates and make a new pending plan (an older one goes stale)."""
        return loop.plan(self)

    def candidate_of(self, entry: PendingPlan, index: int) -> int:
        """``index`` when ``entry``'s plan has that candidate; NotFound otherwise."""
        return loop.candidate_of(entry, index)

    def select(self, index: int) -> None:
        """Highlight candidate ``index`` of the pending plan (from the list or a click in the scene)."""
        loop.select(self, index)

    def reachability(self, pose: Pose) -> tuple[bool, str]:
        """Whether the cell can take a view at ``pose``: its arm's reach, and not inside or against the object."""
        return loop.reachability(self, pose)

    def set_custom(self, pose: Pose) -> CustomPose:
        """Propose a custom pose (the gizmo); reachability is checked now and again on approval."""
        return loop.set_custom(self, pose)

    def approve(self, plan_id: str, index: int | None = None, pose: Pose | None = None) -> dict[str, Any]:
        """Move to candidate ``index`` (or to ``pose``) of the pending plan ``plan_id``, capture, integrate."""
        return loop.approve(self, plan_id, index, pose)

    def change_config(self, changes: dict[str, Any]) -> dict[str, Any]:
        """Change the sections the planner reads on every plan (``loop.MUTABLE_SECTIONS``); journaled."""
        return loop.change_config(self, changes)

    def refit(self, kind: str, t: int) -> Refit:
        """``kind``'s voxels of the current plan fitted at ``t`` components, in the worker; changes nothing."""
        return refit(self, kind, t)

    def discard_last_view(self) -> dict[str, Any]:
        """Rebuild this session from its journal without its last view (workbench/session/discard.py)."""
        return discard_last_view(self)

    # ------------------------------------------------------------------ stop, resume and close

    def stop_plan(self) -> bool:
        """Stop a plan running in the worker; True when one was running."""
        return loop.stop_plan(self)

    def stop(self) -> None:
        """Stop what runs: a plan (killed at once in its worker; the session goes back to its state before it, the
        plan request answers 409), auto mode (after the current action; a plan of it is killed at once), and a
        running move of a cell that can halt its devices (hardware): the arm and the turntable stop at once, the
        session goes to its error state (waited for up to ``STOP_WAIT`` s)."""
        self.stop_plan()
        self.auto.stop()
        if self.cell.halt() is not None:
            self.wait_until(lambda: self.state not in BUSY or not self.cell.halting, STOP_WAIT)

    def replay(self, journal: Journal, progress: Callable[[str, int, int], None] | None = None) -> Rebuilt:
        """This session's state rebuilt from ``journal`` (a resume), to :meth:`restore`."""
        return loop.replay(self, journal, progress)

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
