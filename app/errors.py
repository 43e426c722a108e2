"""Errors of the workbench that map to HTTP statuses (the REST layer turns them into ``{"detail": ...}``)."""

from __future__ import annotations


class WorkbenchError(Exception):
    """Base class: a request the workbench refused, with a one-line reason. Nothing changed."""

    status = 400

    def __init__(self, detail: str) -> None:
        super().__init__(detail)
        self.detail = detail


class NotFoundError(WorkbenchError):
    """Unknown session, candidate or model (404)."""

    status = 404


class ConflictError(WorkbenchError):
    """The session is in the wrong state for this request, or the plan_id is stale or used (409)."""

    status = 409


class UnprocessableError(WorkbenchError):
    """Bad parameters: out of range, an unreachable pose, a model that cannot be loaded (422)."""

    status = 422


class TooLargeError(WorkbenchError):
    """An upload over the size limit (413)."""

    status = 413


class StorageError(WorkbenchError):
    """The data directory cannot be written (the session could not be journaled) (503)."""

    status = 503


class DeviceFaultError(WorkbenchError):
    """A device failed while moving or capturing; the session is now in its error state (503)."""

    status = 503
