"""A calibration's journal: its create request and every pose outcome, so a restart keeps the captures.

One folder per open calibration under ``data_dir/calibrations/<id>/``, holding ``journal.jsonl``: a header line
(the calibration's id and its create request) and one line per pose outcome (``capture`` with the capture's
numbers, ``skip`` with the reason), each appended and fsynced before the request that made it is answered. A
restarted server rebuilds each calibration from its request (the same cell: a simulated one is drawn again from
its seed) and puts the journaled outcomes back (workbench/calibration/book.py); closing a calibration deletes its
folder. A torn last line (a crash in the middle of an append) is the outcome that was never acknowledged: it is
left out.
"""

from __future__ import annotations

import json
import math
import os
import shutil
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from devices.calibration import Capture
from planner import Pose

__all__ = [
    "CALIBRATIONS_DIR",
    "CalibrationJournal",
    "JournaledCalibration",
    "capture_from_json",
    "capture_json",
    "read_calibrations",
]

CALIBRATIONS_DIR = "calibrations"
"""The folder of the calibration journals under ``data_dir``."""
JOURNAL_FILE = "journal.jsonl"


def _numbers(values: Any) -> list[Any]:
    """An array as JSON: NaN (a sphere not seen) as null."""
    return [_numbers(v) if isinstance(v, list | np.ndarray) else (None if math.isnan(v) else float(v)) for v in values]


def _array(values: Any) -> np.ndarray:
    return np.array(values, dtype=float)  # null -> nan


def capture_json(capture: Capture) -> dict[str, Any]:
    """One capture as a journal line's fields."""
    return {
        "label": capture.label,
        "T_base_flange": capture.T_base_flange.to_dict(),
        "plate_angle": float(capture.plate_angle),
        "centres_camera": _numbers(capture.centres_camera.tolist()),
        "fit_rms": _numbers(capture.fit_rms.tolist()),
    }


def capture_from_json(d: dict[str, Any]) -> Capture:
    """The capture of :func:`capture_json`."""
    return Capture(
        Pose.from_dict(d["T_base_flange"]),
        float(d["plate_angle"]),
        _array(d["centres_camera"]).reshape(-1, 3),
        _array(d["fit_rms"]),
        str(d["label"]),
    )


@dataclass
class JournaledCalibration:
    """What a calibration's journal holds: its id, its create request, its pose outcomes in order."""

    id: str
    request: dict[str, Any]
    events: list[dict[str, Any]] = field(default_factory=list)
    directory: Path | None = None


class CalibrationJournal:
    """The append-only journal of one calibration (one writer: the calibration's own claim serialises it)."""

    def __init__(self, directory: Path) -> None:
        self.directory = directory

    @staticmethod
    def create(data_dir: Path, calibration_id: str, request: dict[str, Any]) -> CalibrationJournal:
        """A new journal with its header (OSError when the data directory cannot be written)."""
        directory = data_dir / CALIBRATIONS_DIR / calibration_id
        directory.mkdir(parents=True, exist_ok=False)
        journal = CalibrationJournal(directory)
        journal._write({"kind": "header", "id": calibration_id, "request": request})
        return journal

    def append(self, kind: str, **fields: Any) -> None:
        """One outcome, on disk (fsynced) when this returns; OSError otherwise."""
        self._write({"kind": kind, **fields})

    def _write(self, record: dict[str, Any]) -> None:
        line = json.dumps(record, allow_nan=False) + "\n"
        fd = os.open(self.directory / JOURNAL_FILE, os.O_WRONLY | os.O_CREAT | os.O_APPEND, 0o644)
        try:
            os.write(fd, line.encode())
            os.fsync(fd)
        finally:
            os.close(fd)

    def delete(self) -> None:
        """Forget the calibration (it was closed): its folder goes."""
        shutil.rmtree(self.directory, ignore_errors=True)


def read_calibrations(data_dir: Path) -> list[JournaledCalibration]:
    """Every journaled calibration under ``data_dir`` (oldest first). A journal whose header cannot be read is
    left out (and left on disk); a torn or unreadable event line ends its events."""
    root = data_dir / CALIBRATIONS_DIR
    out = []
    for directory in sorted(root.iterdir() if root.is_dir() else [], key=lambda d: d.stat().st_mtime):
        path = directory / JOURNAL_FILE
        if not path.is_file():
            continue
        lines = path.read_text(errors="replace").splitlines()
        try:
            header = json.loads(lines[0])
            entry = JournaledCalibration(str(header["id"]), dict(header["request"]), directory=directory)
        except (IndexError, ValueError, KeyError, TypeError):
            continue
        for line in lines[1:]:
            try:
                entry.events.append(json.loads(line))
            except ValueError:  # torn by a crash: never acknowledged
                break
        out.append(entry)
    return out
