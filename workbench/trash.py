"""Deleted sessions' journals: moved to ``data_dir/sessions/trash`` on delete, emptied when a server starts.

A delete is recoverable by hand until the next start (move the folder back); the trash is not a session
folder (its name is not a session id), so the registry never lists it.
"""

from __future__ import annotations

import logging
import shutil
import time
from pathlib import Path

from workbench.journal.store import sessions_dir

log = logging.getLogger(__name__)

TRASH = "trash"
"""The trash folder's name inside ``data_dir/sessions``."""


def trash_dir(data_dir: Path) -> Path:
    return sessions_dir(data_dir) / TRASH


def move_to_trash(data_dir: Path, directory: Path) -> Path | None:
    """Move a session folder into the trash (as ``<id>-<unix time>``); None when it is not on disk.

    OSError when the move fails (the folder stays where it was).
    """
    if not directory.is_dir():
        return None
    root = trash_dir(data_dir)
    root.mkdir(parents=True, exist_ok=True)
    target = root / f"{directory.name}-{int(time.time() * 1000)}"
    directory.rename(target)
    return target


def empty_trash(data_dir: Path) -> int:
    """Remove every folder in the trash; returns how many (errors are logged, not raised)."""
    root = trash_dir(data_dir)
    if not root.is_dir():
        return 0
    removed = 0
    for entry in root.iterdir():
        try:
            if entry.is_dir() and not entry.is_symlink():
                shutil.rmtree(entry)
            else:
                entry.unlink()
            removed += 1
        except OSError as exc:
            log.warning("trash: cannot remove %s (%s)", entry, exc)
    return removed
