"""The state machine of a live session: its states and the one table of which action may start from which state.

Each action a person (or auto mode) starts claims the session from one of its allowed states by switching it to
the action's busy state (``·``: an action that holds the lock throughout and has none)::

    new, error ──capture──► capturing
    error ──retry capture──► capturing
    ready, planned, done, error ──plan──► planning
    planned, error ──approve──► moving
    error ──retry move──► moving
    ready, planned, done ──step──► auto
    ready, planned, done ──auto──► auto
    new, ready, planned, done, error ──discard──► discarding
    new, ready, planned, done, error ──configure──► ·
    new ──resume──► ·

When the action ends the session settles (:meth:`SessionCore.enter`): to ``planned`` with a pending plan, else
``done`` once the planner's termination rule fired, else ``ready`` (``new`` before the first view). A fault of
a device or of a worker job leaves it in ``error`` (the map unchanged, the plan whose approval failed pending
again); a refused or stopped action puts back the state it started from. ``done`` still plans and approves;
``error`` is left by ``retry``, by approving the restored plan or by a new plan.

The busy states (``BUSY``) are the ones the table claims; every other state but ``closed`` (a session put to
sleep, :meth:`SessionCore.close_state`) is a resting one. A session listed
from a journal of an earlier server process is not live: :class:`Listed` names how it is listed.
"""

from __future__ import annotations

from dataclasses import dataclass
from enum import StrEnum


class State(StrEnum):
    """The state of a live session (``Session.state``)."""

    NEW = "new"
    CAPTURING = "capturing"
    READY = "ready"
    PLANNING = "planning"
    PLANNED = "planned"
    MOVING = "moving"
    AUTO = "auto"
    DISCARDING = "discarding"
    DONE = "done"
    ERROR = "error"
    CLOSED = "closed"
    """Put to sleep (its journal kept, listed as interrupted) or deleted: no action starts from here."""


class Listed(StrEnum):
    """How a journaled session of an earlier server process is listed (never a live state)."""

    INTERRUPTED = "interrupted"
    """The server stopped during it; resume rebuilds it."""
    DAMAGED = "damaged"
    """Like interrupted, but its journal is damaged; resume recovers what comes before the damage."""


class Action(StrEnum):
    """What a person, a script or auto mode asks a session to do (the keys of :data:`TRANSITIONS`)."""

    CAPTURE = "capture"
    RETRY_CAPTURE = "retry capture"
    PLAN = "plan"
    APPROVE = "approve"
    RETRY_MOVE = "retry move"
    STEP = "step"
    AUTO = "auto"
    DISCARD = "discard"
    CONFIGURE = "configure"
    RESUME = "resume"


@dataclass(frozen=True)
class Transition:
    """Where an action may start (``sources``), the busy state it holds meanwhile (None: it runs under the lock),
    and how a refusal names it (``label``)."""

    sources: frozenset[State]
    busy: State | None
    label: str


def _t(sources: str, busy: State | None, label: str) -> Transition:
    return Transition(frozenset(State(s) for s in sources.split()), busy, label)


TRANSITIONS: dict[Action, Transition] = {
    Action.CAPTURE: _t("new error", State.CAPTURING, "capture"),
    Action.RETRY_CAPTURE: _t("error", State.CAPTURING, "retry"),
    Action.PLAN: _t("ready planned done error", State.PLANNING, "plan"),
    Action.APPROVE: _t("planned error", State.MOVING, "approve"),
    Action.RETRY_MOVE: _t("error", State.MOVING, "retry"),
    Action.STEP: _t("ready planned done", State.AUTO, "step"),
    Action.AUTO: _t("ready planned done", State.AUTO, "start auto mode"),
    Action.DISCARD: _t("new ready planned done error", State.DISCARDING, "discard"),
    Action.CONFIGURE: _t("new ready planned done error", None, "config change"),
    Action.RESUME: _t("new", None, "resume"),
}
"""action -> (allowed sources, busy state): the only list of which state allows what."""

BUSY = frozenset(t.busy for t in TRANSITIONS.values() if t.busy is not None)
"""The states an action holds while it runs: another action meanwhile is refused (409)."""
RESTING = frozenset(State) - BUSY - {State.CLOSED}
"""The states an action may start from (closed: none)."""
