"""Deleted sessions wait in a trash folder until the server restarts, or sooner at its age or size limit:
``data_dir/sessions/.trash/<id>-<deleted ns>``.

Deleting a session marks the journal ``deleted`` and moves the session's folder (journal and frames)
here with one rename; :func:`prune` removes what is older than ``trash_max_age`` and then the oldest until the
trash is under ``trash_max_bytes``. The registry prunes on every delete and at start-up, so frames of deleted
sessions never pile up (a fuzzing run once left 150 MB). Nothing outside the trash folder is ever removed.
"""

from __future__ import annotations

import contextlib
import logging
import os
import re
import shutil
import threading
import time
from dataclasses import dataclass
from pathlib import Path

from workbench.journal.store import SESSION_ID, sessions_dir

log = logging.getLogger(__name__)
TRASH = ".trash"
_ENTRY = re.compile(r"^([0-9a-f]{8})-(\d+)$")


def trash_dir(data_dir: Path) -> Path:
    return sessions_dir(data_dir) / TRASH


@dataclass(frozen=True)
class TrashEntry:
    """One deleted session in the trash: its folder, when it was deleted (s since the epoch) and its size."""

    path: Path
    session_id: str
    deleted: float
    size: int


def move_to_trash(directory: Path) -> Path:
    """Move a session folder (``sessions/<id>``) into the trash; returns where it went."""
    if not SESSION_ID.match(directory.name):
        raise ValueError(f"{directory.name!r}: not a session folder")
    root = trash_dir(directory.parent.parent)
    root.mkdir(parents=True, exist_ok=True)
    target = root / f"{directory.name}-{time.time_ns()}"
    os.replace(directory, target)
    return target


def _size(path: Path) -> int:
    total = 0
    for dirpath, _, files in os.walk(path):
        for name in files:
            with contextlib.suppress(OSError):
                total += (Path(dirpath) / name).lstat().st_size
    return total


_SIZES: dict[Path, int] = {}
"""The size of each trash entry measured so far: a session's folder is not written again once it is in the trash
(a frame already being written at the delete may still land: the size is then short by it until the server
restarts), so each entry is walked once, not at every delete (a server that deleted n sessions walked n folders
at the n-th: 1.3 s of CPU over the 174 deletes of the API's config fuzz test)."""
_SIZES_LOCK = threading.Lock()


def entries(data_dir: Path) -> list[TrashEntry]:
    """What is in the trash, oldest deletion first (names that are not ``<id>-<ns>`` folders are ignored)."""
    root = trash_dir(data_dir)
    if not root.is_dir():
        return []
    found = []
    for path in root.iterdir():
        match = _ENTRY.match(path.name)
        if match and path.is_dir() and not path.is_symlink():
            found.append(TrashEntry(path, match.group(1), int(match.group(2)) / 1e9, _entry_size(path)))
    with _SIZES_LOCK:  # forget the entries of this trash that are gone
        listed = {e.path for e in found}
        for path in [p for p in _SIZES if p.parent == root and p not in listed]:
            del _SIZES[path]
    return sorted(found, key=lambda e: e.deleted)


def _entry_size(path: Path) -> int:
    with _SIZES_LOCK:
        size = _SIZES.get(path)
    if size is None:
        size = _size(path)
        with _SIZES_LOCK:
            _SIZES[path] = size
    return size


def prune(data_dir: Path, max_bytes: int, max_age: float, now: float | None = None) -> list[TrashEntry]:
    """Remove trash entries older than ``max_age`` seconds, then the oldest until the total is <= ``max_bytes``.
    Returns what was removed."""
    now = time.time() if now is None else now
    kept = entries(data_dir)
    removed = [e for e in kept if max_age > 0 and now - e.deleted > max_age]
    kept = [e for e in kept if e not in removed]
    total = sum(e.size for e in kept)
    while kept and total > max_bytes:
        oldest = kept.pop(0)
        total -= oldest.size
        removed.append(oldest)
    for entry in removed:
        shutil.rmtree(entry.path, ignore_errors=True)
        with _SIZES_LOCK:
            _SIZES.pop(entry.path, None)
        log.info("trash: removed session %s (%d bytes)", entry.session_id, entry.size)
    return removed
