"""What to say when the data directory cannot be written: "disk full", how much is free and how much is needed.

A full disk (ENOSPC, or a quota: EDQUOT) is told apart from other write errors, so the API and the page can
say "disk full" and how much space the refused step needs, instead of a bare errno text.
"""

from __future__ import annotations

import contextlib
import errno
import shutil
from pathlib import Path

DISK_FULL = frozenset({errno.ENOSPC, errno.EDQUOT})


def is_disk_full(exc: BaseException) -> bool:
    """Whether ``exc`` is an OSError of a full disk or an exhausted quota."""
    return isinstance(exc, OSError) and exc.errno in DISK_FULL


def megabytes(n: float) -> str:
    """``n`` bytes for a person: ``1.2 MB``, ``3 kB``."""
    return f"{n / 1e6:.1f} MB" if n >= 1e5 else f"{max(1, round(n / 1e3))} kB"


def free_bytes(directory: Path) -> int | None:
    """Free bytes on the file system of ``directory`` (or its nearest existing parent); None when unknown."""
    path = Path(directory)
    while not path.exists() and path != path.parent:
        path = path.parent
    with contextlib.suppress(OSError):
        return shutil.disk_usage(path).free
    return None


def write_failure(exc: OSError, directory: Path, needed: int) -> str:
    """The reason a write of about ``needed`` bytes under ``directory`` failed, for an error message.

    A full disk: ``disk full: 0.0 MB free in DIR, about 0.3 MB needed (free some space and retry)``;
    anything else: the errno text."""
    if not is_disk_full(exc):
        return str(exc.strerror or exc)
    free = free_bytes(directory)
    have = "" if free is None else f"{megabytes(free)} free in {directory}, "
    return f"disk full: {have}about {megabytes(needed)} needed (free some space and retry)"
