"""Re-run a journaled session headless (``nbv replay``): its frames through a fresh planner, checked against
the journal, with the ground truth's coverage where the session was simulated."""

from __future__ import annotations

import time
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path

import numpy as np
from numpy.typing import NDArray

from devices.config import DeviceConfig
from planner.config import from_dict
from workbench.errors import WorkbenchError
from workbench.evaluation.coverage import coverage
from workbench.journal.rebuild import Rebuilt, rebuild, replay_cell
from workbench.journal.store import Journal, read_journal
from workbench.settings import WorkbenchSettings, default_models_dir
from workbench.sources.parts import ground_truth

Coverage = Callable[[NDArray[np.float64]], float]


def ground_truth_coverage(journal: Journal, models_dir: Path | None) -> Coverage | None:
    """cloud -> coverage of the session's ground truth, or None when it is unknown (not a sim session, or its
    model cannot be loaded from ``models_dir`` / the data directory the journal lives in)."""
    header = journal.header
    if header.get("source", {}).get("kind", "sim") != "sim":
        return None
    settings = WorkbenchSettings(
        models_dir=models_dir or default_models_dir(),
        data_dir=journal.directory.parent.parent,
        devices=from_dict(DeviceConfig, header["devices"]),
        journal=False,
    )
    try:
        _, samples = ground_truth(settings, str(header["model"]["name"]), int(header["seed"]))
    except WorkbenchError:
        return None
    return lambda cloud: coverage(samples, cloud)


@dataclass(frozen=True, eq=False)
class JournalCheck:
    """A journal re-run: what was read, what the replay rebuilt, and how long it took (seconds)."""

    journal: Journal
    rebuilt: Rebuilt
    seconds: float


def check_journal(directory: Path, models_dir: Path | None = None) -> JournalCheck:
    """Re-run the session journaled in ``directory``. ValueError for a damaged journal or no frame."""
    journal = read_journal(directory)
    captures = [e for e in journal.of_kind("capture") if e.get("frame")]
    if not captures:
        raise ValueError(f"{directory}: no journaled frame to replay")
    cell = replay_cell(journal)  # reachability as in the session
    t0 = time.perf_counter()
    rebuilt = rebuild(journal, cell, ground_truth_coverage(journal, models_dir))
    return JournalCheck(journal, rebuilt, time.perf_counter() - t0)
