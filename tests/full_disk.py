"""A simulated full disk for tests: ENOSPC at the journal's write boundary (its event writes and its frame files).

Real files, real code paths: only the bytes-to-disk calls fail, the way they do when a disk is full (the
file is created, the write raises ``OSError(ENOSPC)``)."""

from __future__ import annotations

import errno
import io
import os
from collections.abc import Iterator
from contextlib import contextmanager
from typing import Any

import devices.frames
import workbench.journal.store as store


class FullDisk:
    """Simulates a full disk at the journal's write boundary: while ``full``, the journal's ``os.write`` and the
    frame files' writes (``devices.frames``) raise ENOSPC; the files themselves are created, as on a real disk."""

    def __init__(self) -> None:
        self.full = False

    @contextmanager
    def installed(self) -> Iterator[None]:
        disk = self
        real_os = store.os

        class _Os:  # the journal store's ``os`` with a write that fails on a full disk
            def __getattr__(self, name: str) -> Any:
                return getattr(real_os, name)

            @staticmethod
            def write(fd: int, data: Any) -> int:
                if disk.full:
                    raise OSError(errno.ENOSPC, os.strerror(errno.ENOSPC))
                return real_os.write(fd, data)

        class _File(io.FileIO):  # a frame file whose writes fail on a full disk
            def write(self, data: Any) -> int:
                if disk.full:
                    raise OSError(errno.ENOSPC, os.strerror(errno.ENOSPC))
                return super().write(data)

        def frame_open(path: Any, mode: str = "r", *args: Any, **kwargs: Any) -> Any:
            return _File(path, mode.replace("b", "")) if "w" in mode else open(path, mode, *args, **kwargs)

        store.os = _Os()  # type: ignore[assignment]
        devices.frames.open = frame_open  # type: ignore[attr-defined]
        try:
            yield
        finally:
            store.os = real_os
            del devices.frames.open  # type: ignore[attr-defined]
