"""The session journal: a folder per session with a JSON-lines event log and one ``.npz`` per frame.

Layout (format ``nbv-journal``, version ``JOURNAL_VERSION``; docs/journal.md is the reference)::

    <data_dir>/sessions/<id>/journal.jsonl        one JSON object per line, appended
    <data_dir>/sessions/<id>/frames/000001.npz    the DepthFrame of capture 1 (devices/frames.py)

Durability: a frame file is written to a temp name, fsynced and renamed before
the ``capture`` event that names it is appended; each event is one ``write`` of
one line on an ``O_APPEND`` descriptor followed by ``fsync``. A ``kill -9`` can
therefore lose at most the step in flight: a frame without its event (ignored)
or a torn last line (ignored by the reader, cut off when the journal is reopened).
"""

from __future__ import annotations

import errno
import fcntl
import json
import os
import re
import shutil
import threading
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from devices.frames import fsync_dir, load_frame, save_frame
from planner import DepthFrame, Pose
from workbench.journal.storage import write_failure
from workbench.jsonable import jsonable

JOURNAL_FORMAT = "nbv-journal"
JOURNAL_VERSION = 1
JOURNAL_FILE = "journal.jsonl"
SESSION_ID = re.compile(r"^[0-9a-f]{8}$")
"""Session ids are 8 lowercase hex digits; nothing else is ever joined to a path."""


def sessions_dir(data_dir: Path) -> Path:
    return Path(data_dir) / "sessions"


def make_event(seq: int, kind: str, data: dict[str, Any]) -> dict[str, Any]:
    """The event ``{"seq", "time", "kind", **data}`` as the journal stores it (data made JSON-ready)."""
    return {"seq": seq, "time": time.time(), "kind": kind, **jsonable(data)}


class JournalBusyError(ValueError):
    """Another writer (another server on the same data directory) holds the journal."""


class JournalWriter:
    """Appends events (and frames) to one session's journal. Thread-safe; every write is fsynced."""

    def __init__(self, directory: Path, *, fsync: bool = True, seq: int = 0) -> None:
        self.directory = Path(directory)
        self.frames_dir = self.directory / "frames"
        self.fsync = fsync
        self._lock = threading.Lock()
        self._seq = seq
        self.frames_dir.mkdir(parents=True, exist_ok=True)
        self._fd = os.open(self.directory / JOURNAL_FILE, os.O_WRONLY | os.O_APPEND | os.O_CREAT, 0o644)
        try:  # one writer per journal, also across processes (released by the OS when the process dies)
            fcntl.flock(self._fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except OSError:
            os.close(self._fd)
            raise JournalBusyError(f"session {self.directory.name}: its journal is open in another process") from None

    @classmethod
    def create(cls, data_dir: Path, session_id: str, header: dict[str, Any], *, fsync: bool = True) -> JournalWriter:
        """A new journal whose first event is ``session`` with ``header`` (format and version added)."""
        if not SESSION_ID.match(session_id):
            raise ValueError(f"session id {session_id!r}: not 8 hex digits")
        root = sessions_dir(data_dir)
        directory = root / session_id
        directory.mkdir(parents=True, exist_ok=False)
        writer = None
        try:
            writer = cls(directory, fsync=fsync)
            if fsync:
                fsync_dir(root)
            writer.append("session", format=JOURNAL_FORMAT, version=JOURNAL_VERSION, id=session_id, **header)
        except BaseException:  # a full disk: no empty journal stays behind (listed as damaged after a restart)
            if writer is not None:
                writer.close()
            shutil.rmtree(directory, ignore_errors=True)
            raise
        return writer

    @classmethod
    def reopen(cls, journal: Journal, *, fsync: bool = True) -> JournalWriter:
        """Append to an existing journal, first cutting off a torn last line left by a crash."""
        last = journal.events[-1]["seq"] if journal.events else journal.header["seq"]
        writer = cls(journal.directory, fsync=fsync, seq=int(last) + 1)  # locks first, then repairs
        writer.cut_to(journal)
        return writer

    def cut_to(self, journal: Journal) -> None:
        """Cut the file after ``journal``'s last event (``valid_bytes``); a damaged journal is first copied aside
        whole (``keep_damaged_copy``), so what comes after the damage is never lost."""
        path = self.directory / JOURNAL_FILE
        if journal.valid_bytes >= path.stat().st_size:
            return
        if journal.damage is not None or journal.valid_bytes < journal.full_bytes:
            keep_damaged_copy(journal)
        with self._lock:
            os.ftruncate(self._fd, journal.valid_bytes)
            os.fsync(self._fd)
            last = journal.events[-1]["seq"] if journal.events else journal.header["seq"]
            self._seq = int(last) + 1

    def append(self, kind: str, **data: Any) -> dict[str, Any]:
        """Append one event ``{"seq", "time", "kind", **data}`` and make it durable; returns it."""
        with self._lock:
            event = make_event(self._seq, kind, data)
            line = (json.dumps(event, separators=(",", ":"), allow_nan=False) + "\n").encode("utf-8")
            try:
                written = os.write(self._fd, line)
                if written != len(line):  # a disk that filled up mid-line: cut the torn line off again
                    os.ftruncate(self._fd, os.lseek(self._fd, 0, os.SEEK_END) - written)
                    raise OSError(errno.ENOSPC, os.strerror(errno.ENOSPC))
                if self.fsync:
                    os.fsync(self._fd)
            except OSError as exc:
                raise OSError(exc.errno, write_failure(exc, self.directory, len(line))) from exc
            self._seq += 1
            return event

    def write_frame(self, iteration: int, frame: DepthFrame) -> tuple[str, str]:
        """Store the frame of capture ``iteration``; returns (path relative to the journal folder, sha256)."""
        name = f"frames/{iteration:06d}.npz"
        try:
            digest = save_frame(self.directory / name, frame, fsync=self.fsync)
        except OSError as exc:
            raise OSError(exc.errno, write_failure(exc, self.directory, frame.depth.nbytes + 4096)) from exc
        return name, digest

    def write_move_frame(self, iteration: int, k: int, frame: DepthFrame) -> tuple[str, str]:
        """Store the ``k``-th (1-based) frame kept from the move to capture ``iteration``; (path, sha256)."""
        name = f"frames/{iteration:06d}-m{k:03d}.npz"
        try:
            digest = save_frame(self.directory / name, frame, fsync=self.fsync)
        except OSError as exc:
            raise OSError(exc.errno, write_failure(exc, self.directory, frame.depth.nbytes + 4096)) from exc
        return name, digest

    def discard_frame(self, name: str) -> None:
        """Remove a frame that was written but then rejected (best effort)."""
        (self.directory / name).unlink(missing_ok=True)

    def close(self) -> None:
        with self._lock:
            if self._fd >= 0:
                os.close(self._fd)
                self._fd = -1


@dataclass
class Journal:
    """A journal read back: the ``session`` header and the events after it, in order."""

    directory: Path
    header: dict[str, Any]
    events: list[dict[str, Any]] = field(default_factory=list)
    valid_bytes: int = 0
    """Length of the file up to the end of the last complete line (a torn tail or the damage is past it)."""
    torn: bool = False
    damage: str | None = None
    """Where a line before the last is not an event (the events after it were not read), None when intact."""
    dropped_lines: int = 0
    """Lines from the damage to the end of the file (not read)."""
    ends: list[int] = field(default_factory=list)
    """Byte offset of the end of each event's line (``ends[i]`` for ``events[i]``)."""

    header_end: int = 0
    """Byte offset of the end of the header's line."""
    full_bytes: int = 0
    """Length of the file up to the end of its last complete, well-formed line before any cut (a torn tail
    past it is not worth keeping)."""

    def cut(self, count: int) -> None:
        """Keep only the first ``count`` events (a resume that stops at a damaged frame); ``valid_bytes`` follows,
        so :meth:`JournalWriter.reopen` cuts the file there."""
        if count < len(self.events):
            self.full_bytes = max(self.full_bytes, self.valid_bytes)
            self.valid_bytes = self.ends[count - 1] if count > 0 else self.header_end
            del self.events[count:]
            del self.ends[count:]

    @property
    def session_id(self) -> str:
        return str(self.header["id"])

    @property
    def deleted(self) -> bool:
        return any(e["kind"] == "deleted" for e in self.events)

    def of_kind(self, *kinds: str) -> list[dict[str, Any]]:
        return [e for e in self.events if e["kind"] in kinds]

    def frame(self, event: dict[str, Any]) -> DepthFrame:
        """The DepthFrame of a ``capture`` event (checked against its sha256). ValueError if missing or damaged."""
        name = str(event["frame"])
        if not re.fullmatch(r"frames/\d{6}\.npz", name):
            raise ValueError(f"capture {event.get('iteration')}: bad frame name {name!r}")
        return load_frame(self.directory / name, event.get("frame_sha256"))

    def move_frames(self, event: dict[str, Any]) -> list[tuple[DepthFrame, Pose]]:
        """The frames kept from the move to a ``capture`` event's view (its ``move_frames``, each checked against its
        sha256) with their registered poses, in stamp order; [] for a view without (and a journal of an older
        build). ValueError if one is missing or damaged."""
        out = []
        for entry in event.get("move_frames") or []:
            name = str(entry["frame"])
            if not re.fullmatch(r"frames/\d{6}-m\d{3}\.npz", name):
                raise ValueError(f"capture {event.get('iteration')}: bad move frame name {name!r}")
            out.append(
                (load_frame(self.directory / name, entry.get("frame_sha256")), Pose.from_dict(entry["pose_used"]))
            )
        return out


def read_journal(directory: str | Path) -> Journal:
    """Read ``directory/journal.jsonl``. ValueError when it is missing, not a journal or of another version.

    A last line without its newline, or one that is not JSON, is the torn write of a
    crash: it is left out (``torn`` is set). A bad line before the last is damage: the
    events before it are read, ``damage`` says where, ``dropped_lines`` counts what follows.
    """
    directory = Path(directory)
    path = directory / JOURNAL_FILE
    try:
        data = path.read_bytes()
    except OSError as exc:
        raise ValueError(f"{directory.name}: no journal ({exc.strerror})") from None
    events: list[dict[str, Any]] = []
    ends: list[int] = []
    valid = 0
    damage: str | None = None
    dropped = 0
    *complete, tail = data.split(b"\n")
    torn = tail != b""  # a last line without its newline: the write was cut
    for i, raw in enumerate(complete):
        try:
            event = json.loads(raw)
            if not isinstance(event, dict) or "kind" not in event or "seq" not in event:
                raise ValueError("not an event")
        except ValueError:
            if i == len(complete) - 1:  # garbage in the last line (power loss): also a torn write
                torn = True
                break
            damage = f"{JOURNAL_FILE} line {i + 1} is damaged"
            dropped = len(complete) - i + (1 if torn else 0)
            break
        events.append(event)
        valid += len(raw) + 1
        ends.append(valid)
    if not events or events[0]["kind"] != "session":
        raise ValueError(f"{directory.name}: not a session journal (no 'session' event first)")
    header = events[0]
    if header.get("format") != JOURNAL_FORMAT:
        raise ValueError(f"{directory.name}: format {header.get('format')!r}, expected {JOURNAL_FORMAT!r}")
    if header.get("version") != JOURNAL_VERSION:
        raise ValueError(
            f"{directory.name}: journal version {header.get('version')!r}; this build reads {JOURNAL_VERSION}"
        )
    return Journal(directory, header, events[1:], valid, torn, damage, dropped, ends[1:], ends[0], valid)


def keep_damaged_copy(journal: Journal) -> Path:
    """Copy the whole journal file aside (``journal.damaged-<time>.jsonl``) before a resume cuts it at the damage."""
    source = journal.directory / JOURNAL_FILE
    target = journal.directory / f"journal.damaged-{time.time_ns()}.jsonl"
    target.write_bytes(source.read_bytes())
    return target


def in_use(directory: Path) -> bool:
    """Whether a live writer (this or another process) holds the journal in ``directory``."""
    try:
        fd = os.open(Path(directory) / JOURNAL_FILE, os.O_RDONLY)
    except OSError:
        return False
    try:
        fcntl.flock(fd, fcntl.LOCK_SH | fcntl.LOCK_NB)
    except OSError:
        return True
    finally:
        os.close(fd)  # closing drops the probe's lock
    return False


def list_journals(data_dir: Path) -> list[Path]:
    """Session folders (named like a session id, not symlinks) under ``data_dir/sessions``, oldest first."""
    root = sessions_dir(data_dir)
    if not root.is_dir():
        return []
    found = [
        p
        for p in root.iterdir()
        if SESSION_ID.match(p.name) and p.is_dir() and not p.is_symlink() and (p / JOURNAL_FILE).is_file()
    ]
    return sorted(found, key=lambda p: (p / JOURNAL_FILE).stat().st_mtime)
