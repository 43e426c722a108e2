"""The journal store: torn tails survive, damage and other versions are refused, one writer at a time."""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from workbench.journal.store import JOURNAL_FILE, JournalBusyError, JournalWriter, read_journal


def write_journal(tmp_path: Path, n: int = 3) -> Path:
    writer = JournalWriter.create(tmp_path, "0123abcd", {"model": {"name": "x", "kind": "builtin"}, "seed": 0})
    for i in range(n):
        writer.append("note", i=i)
    writer.close()
    return tmp_path / "sessions" / "0123abcd"


def test_a_torn_last_line_is_ignored_then_cut_off(tmp_path: Path) -> None:
    directory = write_journal(tmp_path)
    path = directory / JOURNAL_FILE
    good = path.read_bytes()
    for tail in (b'{"seq":4,"time":1,"kind":"no', b'{"seq":4,"time":1,"kind":"note"}', b"\x00\x00\x00\n"):
        path.write_bytes(good + tail)
        journal = read_journal(directory)
        assert journal.torn and [e["i"] for e in journal.events] == [0, 1, 2] and journal.valid_bytes == len(good)
        writer = JournalWriter.reopen(journal)
        writer.append("note", i=3)
        writer.close()
        journal = read_journal(directory)
        assert not journal.torn and [e["i"] for e in journal.events] == [0, 1, 2, 3]
        assert [e["seq"] for e in journal.events] == [1, 2, 3, 4]
        path.write_bytes(good)


def test_damage_is_read_up_to_and_other_versions_are_refused(tmp_path: Path) -> None:
    directory = write_journal(tmp_path)
    path = directory / JOURNAL_FILE
    lines = path.read_bytes().split(b"\n")
    path.write_bytes(b"\n".join([lines[0], b"garbage", *lines[2:]]))
    damaged = read_journal(directory)  # the header reads; the damage is reported, what follows is not read
    assert damaged.damage == "journal.jsonl line 2 is damaged" and damaged.events == []
    assert damaged.dropped_lines == len(lines) - 2 and damaged.valid_bytes == len(lines[0]) + 1
    head = json.loads(lines[0])
    path.write_bytes(json.dumps({**head, "version": 99}).encode() + b"\n")
    with pytest.raises(ValueError, match="journal version 99"):
        read_journal(directory)
    path.write_bytes(b'{"seq":0,"time":0,"kind":"note"}\n')
    with pytest.raises(ValueError, match="not a session journal"):
        read_journal(directory)
    with pytest.raises(ValueError, match="no journal"):
        read_journal(tmp_path / "nowhere")


def test_one_writer_per_journal(tmp_path: Path) -> None:
    directory = write_journal(tmp_path)
    first = JournalWriter.reopen(read_journal(directory))
    with pytest.raises(JournalBusyError, match="another process"):
        JournalWriter.reopen(read_journal(directory))
    first.close()
    JournalWriter.reopen(read_journal(directory)).close()
