"""Deleted sessions go to the trash (one rename) and leave it by age, then by size, oldest first."""

from __future__ import annotations

import time
from pathlib import Path

from tests.helpers import SMALL
from workbench.journal.store import JOURNAL_FILE, list_journals
from workbench.journal.trash import entries, move_to_trash, prune, trash_dir
from workbench.registry.registry import SessionRegistry
from workbench.settings import WorkbenchSettings


def fake_session(data_dir: Path, sid: str, size: int) -> Path:
    directory = data_dir / "sessions" / sid
    (directory / "frames").mkdir(parents=True)
    (directory / JOURNAL_FILE).write_text("{}\n")
    (directory / "frames" / "000001.npz").write_bytes(b"x" * size)
    return directory


def test_prune_removes_by_age_then_by_size_oldest_first(tmp_path: Path) -> None:
    moved = []
    for i, sid in enumerate(["0000000a", "0000000b", "0000000c", "0000000d"]):
        moved.append(move_to_trash(fake_session(tmp_path, sid, 1000 * (i + 1))))
        time.sleep(0.002)
    assert [e.session_id for e in entries(tmp_path)] == ["0000000a", "0000000b", "0000000c", "0000000d"]
    assert not (tmp_path / "sessions" / "0000000a").exists() and list_journals(tmp_path) == []
    now = entries(tmp_path)[0].deleted + 10.0
    assert prune(tmp_path, max_bytes=10**9, max_age=3600, now=now) == []
    (tmp_path / "sessions" / ".trash" / "notes.txt").write_text("not ours")  # never touched
    removed = prune(tmp_path, max_bytes=8000, max_age=3600, now=now)  # 1+2+3+4 kB (+ journals) > 8 kB
    assert [e.session_id for e in removed] == ["0000000a", "0000000b"]
    assert [e.session_id for e in entries(tmp_path)] == ["0000000c", "0000000d"]
    removed = prune(tmp_path, max_bytes=10**9, max_age=5.0, now=now + 100)
    assert [e.session_id for e in removed] == ["0000000c", "0000000d"] and entries(tmp_path) == []
    assert (trash_dir(tmp_path) / "notes.txt").read_text() == "not ours"


def test_delete_moves_the_frames_out_and_the_limit_removes_them(tmp_path: Path) -> None:
    settings = WorkbenchSettings(models_dir=tmp_path / "models", data_dir=tmp_path / "data", trash_max_bytes=1)
    registry = SessionRegistry(settings)
    try:
        session = registry.create(config=SMALL)
        session.capture()
        directory = settings.data_dir / "sessions" / session.id
        assert (directory / "frames" / "000001.npz").is_file()
        registry.delete(session.id)
        assert not directory.exists() and entries(settings.data_dir) == []  # over 1 byte: removed at once
    finally:
        registry.close()
    kept = WorkbenchSettings(models_dir=tmp_path / "models", data_dir=tmp_path / "data2")
    registry = SessionRegistry(kept)
    try:
        session = registry.create(config=SMALL)
        registry.delete(session.id)
        (entry,) = entries(kept.data_dir)
        assert entry.session_id == session.id and (entry.path / JOURNAL_FILE).is_file()
    finally:
        registry.close()


def test_each_entry_is_measured_once_and_forgotten_when_it_leaves(tmp_path: Path, monkeypatch) -> None:
    """A delete prunes the trash: the sizes of what was there already are kept (a trash entry is not written
    again), so the n-th delete walks one folder, not n; an entry that left is forgotten, and the totals are those
    of a fresh walk."""
    from workbench.journal import trash

    walked: list[str] = []
    size = trash._size
    monkeypatch.setattr(trash, "_size", lambda path: walked.append(path.name[:8]) or size(path))
    for i, sid in enumerate(["0000001a", "0000001b", "0000001c"]):
        move_to_trash(fake_session(tmp_path, sid, 1000 * (i + 1)))
        prune(tmp_path, max_bytes=10**9, max_age=3600)
        time.sleep(0.002)
    assert walked == ["0000001a", "0000001b", "0000001c"]
    assert [e.size for e in entries(tmp_path)] == [size(e.path) for e in entries(tmp_path)]
    assert [e.size - 1000 * (i + 1) for i, e in enumerate(entries(tmp_path))] == [3] * 3  # the frame + "{}\n"
    removed = prune(tmp_path, max_bytes=6000, max_age=3600)  # 6,009 bytes: the oldest goes
    assert [e.session_id for e in removed] == ["0000001a"]
    assert {p.name[:8] for p in trash._SIZES if p.parent == trash_dir(tmp_path)} == {"0000001b", "0000001c"}
    move_to_trash(fake_session(tmp_path, "0000001a", 10))  # the same session id again: a new entry, walked
    assert [e.size for e in entries(tmp_path)] == [2003, 3003, 13] and walked[-1] == "0000001a"
