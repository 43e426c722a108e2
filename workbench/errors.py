"""The domain errors of a supervised scan: each names what kind of refusal it is, never how to transport it.

``app/`` maps each type to an HTTP status (app/errors.py); the CLI maps them to exit codes. A caller
never matches message text. Every error carries a one-line ``detail``; nothing changed when one is raised
(except :class:`DeviceFault`, after which the session is in its error state with the map unchanged).
"""

from __future__ import annotations


class WorkbenchError(Exception):
    """Base class: a request the workbench refused, with a one-line reason."""

    def __init__(self, detail: str) -> None:
        super().__init__(detail)
        self.detail = detail


class NotFound(WorkbenchError):  # noqa: N818 - named for the domain, as the transport never sees them
    """Unknown session, candidate, model or recording."""


class Conflict(WorkbenchError):  # noqa: N818 - named for the domain, as the transport never sees them
    """The session is in the wrong state for this request, or the plan_id is stale or used."""


class Invalid(WorkbenchError):  # noqa: N818 - named for the domain, as the transport never sees them
    """Bad parameters: out of range, wrong type, a model that cannot be loaded, a bad recording."""


class Unreachable(Invalid):
    """The cell cannot take a view at the requested pose (out of reach, inside the object)."""


class TooLarge(WorkbenchError):  # noqa: N818 - named for the domain, as the transport never sees them
    """An upload or a request over a size limit."""


class StorageFault(WorkbenchError):  # noqa: N818 - named for the domain, as the transport never sees them
    """The data directory cannot be written (the session could not be journaled)."""


class DeviceFault(WorkbenchError):  # noqa: N818 - named for the domain, as the transport never sees them
    """A device failed while moving or capturing; the session is now in its error state."""


class Gone(WorkbenchError):  # noqa: N818 - named for the domain, as the transport never sees them
    """The session was deleted while this request ran (its job was killed with it): there is nothing to retry."""


class AtCapacity(WorkbenchError):  # noqa: N818 - named for the domain, as the transport never sees them
    """As many sessions are live as the server allows (``max_live_sessions``) and none of them is idle."""


class Interrupted(WorkbenchError):  # noqa: N818 - named for the domain, as the transport never sees them
    """A read or job was cut off by something else than the request itself (a Stop, the session put to sleep or
    closed, shutdown): the request was valid and changed nothing; asking again answers it."""
