"""Creates (and resumes) in flight: their progress, for the page that follows one, and their cancellation.

A create on a big mesh takes seconds (reading, checking and sampling the mesh, building the cell). The page
names its create with a ``progress_id`` it chose, follows its progress by that name and may cancel
it: a cancelled create stops at its next stage with :class:`Conflict`, nothing
created, nothing kept.
"""

from __future__ import annotations

import re
import threading
from collections.abc import Callable, Iterator, Sequence
from contextlib import contextmanager

from workbench.errors import Conflict, Invalid
from workbench.progress import CREATE_STAGES, Progress, Tracker

PROGRESS_ID = re.compile(r"^[A-Za-z0-9_-]{8,64}$")
"""What a page may name its create with."""


def resume_id(session_id: str) -> str:
    """The progress id of the resume of ``session_id`` (a page names its creates otherwise: not ``resume-``)."""
    return f"resume-{session_id}"


Listener = Callable[[str, "Progress | None"], None]


class Creation:
    """One create: ``stage(name)`` reports the next stage, or raises Conflict when it was cancelled."""

    def __init__(self, progress_id: str | None, sink: Callable[[Progress | None], None]) -> None:
        self.progress_id = progress_id
        self.cancelled = threading.Event()
        self.tracker = Tracker(sink)

    def stage(self, name: str) -> None:
        if self.cancelled.is_set():
            raise Conflict(f"create {self.progress_id}: cancelled")
        self.tracker.stage(name)


class Creations:
    """The creates in flight of one registry, by ``progress_id``; ``listeners`` hear each one's progress."""

    def __init__(self) -> None:
        self._lock = threading.Lock()
        self._running: dict[str, Creation] = {}
        self.listeners: list[Listener] = []

    @contextmanager
    def run(
        self,
        progress_id: str | None,
        operation: str = "create",
        stages: Sequence[str] = CREATE_STAGES,
        stoppable: bool = True,
    ) -> Iterator[Creation]:
        """A create (or a resume: ``operation``, ``stages``), followed under ``progress_id`` (None: by nobody)
        from its start to its end; ``stoppable``: it may be cancelled (when it has an id)."""
        if progress_id is not None and not PROGRESS_ID.match(progress_id):
            raise Invalid(f"progress_id: 8 to 64 letters, digits, '_' or '-', got {progress_id!r}")

        def sink(progress: Progress | None) -> None:
            if progress_id is not None:
                for listener in list(self.listeners):
                    listener(progress_id, progress)

        creation = Creation(progress_id, sink)
        if progress_id is not None:
            with self._lock:
                if progress_id in self._running:
                    raise Conflict(f"progress_id {progress_id!r}: a create with this id is running")
                self._running[progress_id] = creation
        creation.tracker.begin(operation, stages, stoppable=stoppable and progress_id is not None)
        try:
            yield creation
        finally:
            creation.tracker.end()
            if progress_id is not None:
                with self._lock:
                    self._running.pop(progress_id, None)

    def progress(self, progress_id: str) -> Progress | None:
        """Where the create ``progress_id`` is (None when none runs under that id)."""
        with self._lock:
            creation = self._running.get(progress_id)
        return None if creation is None else creation.tracker.current

    def cancel(self, progress_id: str) -> bool:
        """Cancel the create ``progress_id`` at its next stage; False when none runs under that id."""
        with self._lock:
            creation = self._running.get(progress_id)
        if creation is None:
            return False
        creation.cancelled.set()
        return True
