"""Rebuild a session from its journal: re-integrate the journaled frames through a fresh Planner.

The planner's state after a frame depends on every earlier integrate *and plan*
(the fits are warm-started, the fits' RNG advances), so the events are replayed
in their journaled order: ``capture`` -> ``Planner.integrate`` of the frames kept from the move to it (capture
during moves, ``move_frames``), then of the stored frame,
``plan`` -> ``Planner.plan`` with the cell's reachability, ``config`` -> the same
change; a discarded view (workbench/journal/discard.py) is left out. Every step is checked against what the journal recorded (points, voxel
counts, iteration, coverage, best view and its score); differences are listed
in ``Rebuilt.mismatches``. Used by a resume, a discard and ``nbv replay``.
"""

from __future__ import annotations

import contextlib
import math
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any

import numpy as np
from numpy.typing import NDArray

from devices.cell import ScanCell
from devices.config import DeviceConfig
from devices.replay import ReplayCell
from planner import Planner, PlannerConfig, PlanResult, Pose
from planner.config import from_dict, without_removed
from planner.planner import IntegrationReport
from workbench.journal.discard import without_discarded
from workbench.journal.store import Journal
from workbench.planning import plan_in
from workbench.session.record import SessionRecord
from workbench.session.summaries import best_of, capture_fields, plan_fields, voxel_counts
from workbench.session.values import PendingPlan
from workbench.surface.live import SurfaceUpdate

SCORE_RTOL = 1e-9
"""Relative tolerance of a replayed score (the same computation on the same build is exact)."""
COVERAGE_ATOL = 1e-3
"""Absolute tolerance of a replayed coverage: open3d's ICP sums in parallel, so a pose can differ in its last
bits when the original ran beside other sessions; a few of the 10 000 surface samples at the 5 mm radius may
flip. Points and voxel counts are still compared exactly."""


@dataclass
class ReplayedCapture:
    """One journaled capture re-integrated, and the plan made after it (if one was journaled)."""

    event: dict[str, Any]
    report: IntegrationReport
    voxels: dict[str, int]
    coverage: float | None
    plans: list[tuple[dict[str, Any], PlanResult]] = field(default_factory=list)
    views: tuple[Pose, ...] | None = None
    """The views taken up to this capture (Poses), kept when the rebuild was asked for them (a timeline)."""
    cloud: NDArray[np.float64] | None = None
    """(N, 3) the registered cloud after this capture, kept when the rebuild was asked for it (a timeline)."""


@dataclass
class Rebuilt:
    """A session's state rebuilt from its journal."""

    planner: Planner
    config: PlannerConfig
    record: SessionRecord
    captures: list[ReplayedCapture]
    pending: PendingPlan | None
    last: PendingPlan | None
    used: set[str]
    stale: set[str]
    mismatches: list[str]
    interrupted: str | None
    """plan_id of a decision whose capture never happened (the step in flight at the crash)."""
    device_state: dict[str, Any] | None
    kept: int = 0
    """How many of the journal's events (``Journal.events``, discarded ones included) come before the first damaged
    one: all of them unless one was damaged. A resume cuts the journal there; counting the replayed events instead
    (a discarded capture is not replayed) cut a journal with a discard short: the discard, or the views after it,
    came back or were lost at the next restart."""
    dropped: list[str] = field(default_factory=list)
    """What was lost: the damaged event or frame, and how many events after it (empty when nothing was)."""
    surface: SurfaceUpdate | None = None
    """The surface of the kept captures (workbench/journal/surface.py), when the rebuild was asked for it."""


def _close(a: float | None, b: float | None, rtol: float = SCORE_RTOL) -> bool:
    if a is None or b is None:
        return a is b
    return math.isclose(a, b, rel_tol=rtol, abs_tol=1e-12)


REPLAY_STAGE = "replaying the journal"
"""The stage a rebuild reports (its items: the captures and plans replayed)."""
HEAVY_KINDS = frozenset({"capture", "plan"})
"""The events whose replay takes time (integrating a frame, planning)."""


def replay_cell(journal: Journal) -> ReplayCell:
    """A cell that judges reachability as the journaled session's did, playing back its frames (no devices)."""
    captures = [e for e in journal.of_kind("capture") if e.get("frame")]
    devices = from_dict(DeviceConfig, journal.header["devices"])
    return ReplayCell([journal.frame(e) for e in captures], devices.cell)


def rebuild(
    journal: Journal,
    cell: ScanCell,
    coverage: Callable[[NDArray[np.float64]], float] | None = None,
    progress: Callable[[str, int, int], None] | None = None,
    keep_scene: bool = False,
) -> Rebuilt:
    """Replay ``journal`` through a fresh Planner, up to the first damaged event or frame (``Rebuilt.dropped``
    says what was left out). ValueError when the header itself is unusable.

    cell: the session's cell, asked as the session asked it when planning (:func:`workbench.planning.plan_in`).
    coverage: cloud -> coverage of the ground truth, when it is known (simulation).
    progress: ``(REPLAY_STAGE, done, total)`` over the captures and plans replayed (the heavy events).
    keep_scene: each replayed capture keeps the views and the cloud after it (workbench/journal/timeline.py).
    """
    header = journal.header
    config = PlannerConfig.from_journal(header["config"])
    planner = Planner(config, evaluator=str(header.get("planner", "projection")))
    record = SessionRecord.from_header(header)
    captures: list[ReplayedCapture] = []
    mismatches: list[str] = []
    pending: PendingPlan | None = None
    last: PendingPlan | None = None
    in_flight: PendingPlan | None = None
    used: set[str] = set()
    stale: set[str] = set()
    device_state: dict[str, Any] | None = None
    dropped: list[str] = []
    if journal.damage is not None:
        dropped.append(f"{journal.damage}: {journal.dropped_lines} line(s) from there on")
    kept = len(journal.events)
    events = without_discarded(journal.events)
    heavy = sum(1 for ev in events if ev.get("kind") in HEAVY_KINDS)
    done = 0
    for ev in events:
        if progress is not None and ev.get("kind") in HEAVY_KINDS:
            progress(REPLAY_STAGE, done, heavy)
            done += 1
        try:
            in_flight, pending, last, config, device_state = _replay_one(
                ev,
                journal,
                planner,
                record,
                captures,
                mismatches,
                cell,
                coverage,
                (in_flight, pending, last, config, device_state),
                used,
                stale,
            )
            if keep_scene and ev.get("kind") == "capture" and captures and captures[-1].event is ev:
                captures[-1].views = tuple(planner.views)
                captures[-1].cloud = np.array(planner.cloud, dtype=np.float64, copy=True)
        except (ValueError, KeyError, TypeError) as exc:
            kept = next(i for i, e in enumerate(journal.events) if e is ev)  # its place in the whole journal
            rest = len(journal.events) - kept - 1
            dropped.insert(0, f"event {ev.get('seq')} ({ev.get('kind')}): {exc}; it and {rest} later event(s) dropped")
            break
    if progress is not None:
        progress(REPLAY_STAGE, done, heavy)
    interrupted = None
    if in_flight is not None:  # killed between the decision and its capture: the step never completed
        interrupted = in_flight.plan_id
        pending = in_flight
    return Rebuilt(
        planner,
        config,
        record,
        captures,
        pending,
        last,
        used,
        stale,
        mismatches,
        interrupted,
        device_state,
        kept,
        dropped,
    )


_State = tuple[PendingPlan | None, PendingPlan | None, PendingPlan | None, PlannerConfig, dict[str, Any] | None]


def _replay_one(
    ev: dict[str, Any],
    journal: Journal,
    planner: Planner,
    record: SessionRecord,
    captures: list[ReplayedCapture],
    mismatches: list[str],
    cell: ScanCell,
    coverage: Callable[[NDArray[np.float64]], float] | None,
    state: _State,
    used: set[str],
    stale: set[str],
) -> _State:
    """Replay one event; returns (in_flight, pending, last, config, device_state) after it."""
    in_flight, pending, last, config, device_state = state

    def differ(what: str, recorded: Any, replayed: Any) -> None:
        mismatches.append(f"{what}: journal {recorded!r}, replay {replayed!r}")

    kind = ev["kind"]
    if kind == "config":
        config = config.replace(**without_removed(ev["changes"]))
        planner.config = config
        record.apply(ev)
    elif kind == "capture":
        it = int(ev["iteration"])
        frame = journal.frame(ev)
        for move_frame, _ in journal.move_frames(ev):  # capture during moves: the move's frames, then the view
            planner.integrate(move_frame, move_frame=True)
        report = planner.integrate(frame)
        voxels = voxel_counts(planner)
        cov = float(coverage(planner.cloud)) if coverage is not None else None
        if report.iteration != it:
            differ(f"capture {it}: iteration", it, report.iteration)
        if report.n_points_total != ev["points"]:
            differ(f"capture {it}: points", ev["points"], report.n_points_total)
        if ev.get("voxels") is not None and voxels != ev["voxels"]:
            differ(f"capture {it}: voxel counts", ev["voxels"], voxels)
        if cov is not None and ev.get("coverage") is not None and abs(cov - ev["coverage"]) > COVERAGE_ATOL:
            differ(f"capture {it}: coverage", ev["coverage"], cov)
        # a journal of an older build lacks some fields: the replay supplies them, the journal's values win
        record.apply({**capture_fields(report, voxels, cov), **ev})
        captures.append(ReplayedCapture(ev, report, voxels, cov))
        if in_flight is not None:
            used.add(in_flight.plan_id)
            in_flight = None
        device_state = ev.get("device_state")
        if device_state is not None:  # the next plan sees the arm where the session had it
            with contextlib.suppress(ValueError):
                cell.restore_device_state(device_state)
    elif kind == "plan":
        plan = plan_in(cell, planner)
        best, recorded = best_of(plan), ev.get("best")
        where = f"plan {ev['plan_id']} (view {plan.iteration})"
        if (best is None) != (recorded is None):
            differ(f"{where}: best view", recorded, best)
        elif best is not None and recorded is not None:
            if best["index"] != recorded["index"]:
                differ(f"{where}: best index", recorded["index"], best["index"])
            elif not _close(best["score"], recorded["score"]):
                differ(f"{where}: best score", recorded["score"], best["score"])
        entry = PendingPlan(str(ev["plan_id"]), plan, float(ev["time"]))
        if pending is not None:
            stale.add(pending.plan_id)
        pending = last = entry
        record.apply({**plan_fields(plan), **ev})
        if captures:
            captures[-1].plans.append((ev, plan))
    else:
        record.apply(ev)
        if kind in ("decision", "retry") and pending is not None and ev.get("plan_id") == pending.plan_id:
            in_flight, pending = pending, None
        elif kind == "error" and in_flight is not None and ev.get("restored_plan") == in_flight.plan_id:
            pending, in_flight = in_flight, None
    return in_flight, pending, last, config, device_state
