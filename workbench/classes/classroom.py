"""A class as it is stored: its join code, what its seats scan, and which session each seat is. One JSON file a
class in ``data_dir/classes``, replaced atomically on every change, so a class survives a server restart."""

from __future__ import annotations

import json
import os
import secrets
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import Any

__all__ = ["CODE_ALPHABET", "ClassRoom", "Seat", "classes_dir", "new_code", "read_classes"]

CODE_ALPHABET = "ABCDEFGHJKMNPQRSTUVWXYZ23456789"
"""Join codes use letters and digits that read unambiguously on a projector (no 0/O, 1/I/L)."""
CODE_LENGTH = 6


def new_code() -> str:
    """A fresh join code (31^6, about 9e8 codes)."""
    return "".join(secrets.choice(CODE_ALPHABET) for _ in range(CODE_LENGTH))


def classes_dir(data_dir: Path) -> Path:
    return data_dir / "classes"


@dataclass
class Seat:
    """One student's place: a session of its own."""

    number: int
    """1-based, as the board shows it."""
    session: str
    model: str
    joined: bool = False
    """A student took this seat (``join``); the next join takes the first seat nobody joined."""
    resets: int = 0
    """How often the teacher reset it (each reset is a new session on the seat)."""


@dataclass
class ClassRoom:
    """A teacher's class: N seats scanning one object or a list (round robin), one planner, guided or not."""

    id: str
    code: str
    planner: str
    models: list[str]
    guided: bool
    config: dict[str, Any]
    created: float
    seats: list[Seat] = field(default_factory=list)
    paused: bool = False
    """The teacher paused the class: every seat refuses changes until it is resumed."""

    def seat(self, number: int) -> Seat:
        from workbench.errors import NotFound

        if not 1 <= number <= len(self.seats):
            raise NotFound(f"class {self.id}: no seat {number} (seats 1 to {len(self.seats)})")
        return self.seats[number - 1]

    def to_json(self) -> dict[str, Any]:
        return asdict(self)

    @classmethod
    def from_json(cls, data: dict[str, Any]) -> ClassRoom:
        seats = [Seat(**s) for s in data.get("seats", [])]
        return cls(**{**data, "seats": seats})

    def save(self, data_dir: Path) -> None:
        """Write the class's file atomically (a crash leaves the old file or the new one, never half of one)."""
        directory = classes_dir(data_dir)
        directory.mkdir(parents=True, exist_ok=True)
        path = directory / f"{self.id}.json"
        tmp = path.with_suffix(".json.tmp")
        with tmp.open("w", encoding="utf-8") as f:
            json.dump(self.to_json(), f, indent=1)
            f.flush()
            os.fsync(f.fileno())
        os.replace(tmp, path)

    def remove(self, data_dir: Path) -> None:
        (classes_dir(data_dir) / f"{self.id}.json").unlink(missing_ok=True)


def read_classes(data_dir: Path) -> tuple[list[ClassRoom], list[str]]:
    """The stored classes, and a line per file that could not be read (skipped, left in place)."""
    rooms: list[ClassRoom] = []
    problems: list[str] = []
    directory = classes_dir(data_dir)
    if not directory.is_dir():
        return rooms, problems
    for path in sorted(directory.glob("*.json")):
        try:
            rooms.append(ClassRoom.from_json(json.loads(path.read_text(encoding="utf-8"))))
        except (OSError, ValueError, TypeError, KeyError) as exc:
            problems.append(f"{path.name}: {exc}")
    return rooms, problems
