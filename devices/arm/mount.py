"""Where to mount an arm: the share of the candidate hemisphere it reaches from a mount, and a search for the best.

:func:`reach_report` asks the arm model (:class:`devices.arm.kinematics.ArmKinematics`: plate angle, IK, joint
limits, collisions with the plate, table, object box and itself, the plate's turn) about every view of the
planner's candidate hemisphere about an object of a given size standing on the plate (a box of that size, centred
on the plate axis): the reachable share, per parallel, and the reasons for the rest. :func:`search_mount` tries
mounts on the -x side of the plate (distance from the plate axis and height) on a coarser hemisphere and reports
the best at full resolution. ``nbv arms check`` prints them; the page colours the hemisphere with
:func:`hemisphere_reachability`.
"""

from __future__ import annotations

import dataclasses
import math
from collections import Counter
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from devices.arm.config import ArmConfig
from devices.config import CellConfig
from planner.candidates import propose_candidates
from planner.config import PlannerConfig
from planner.types import BoundingBox, Candidate

SEARCH_DISTANCES = (0.45, 0.55, 0.65, 0.75, 0.85, 0.95, 1.05)
"""Mount distances from the plate axis tried by the search, metres (scaled by the preset's ``cell_scale``)."""
SEARCH_HEIGHTS = (-0.05, 0.0, 0.15, 0.3)
"""Mount heights above the plate top tried by the search, metres (scaled by the preset's ``cell_scale``; none below
the table top, ``ArmConfig.table_height``)."""
SEARCH_CANDIDATES = 60
"""Candidates of the coarse hemisphere each mount of the search is scored on (the best is re-scored on the full
one)."""


@dataclass(frozen=True)
class ReachReport:
    """How much of the candidate hemisphere an arm reaches from one mount."""

    arm: str
    """The preset name or URDF path."""
    base: tuple[float, float, float]
    """The mount, cell base frame, metres."""
    object_size: float
    """The object's size (a box of this side on the plate), metres."""
    candidates: int
    """Views of the hemisphere."""
    reachable: int
    """Of them reachable."""
    per_parallel: tuple[tuple[float, int, int], ...]
    """(elevation in degrees, reachable, views) of each parallel, lowest first."""
    reasons: dict[str, int] = field(default_factory=dict)
    """Why the others are not: reason (``no_ik``, ``joint_limit``, ``collision:<link>:<obstacle>``, ...) -> views."""
    searched: tuple[tuple[float, float, float], ...] = ()
    """(distance, height, share on the coarse hemisphere) of every mount the search tried (empty: no search)."""

    @property
    def reachable_share(self) -> float:
        """reachable / candidates."""
        return self.reachable / self.candidates if self.candidates else 0.0

    def to_json(self) -> dict[str, Any]:
        """The report as JSON-ready data (``nbv arms check --json``)."""
        return {
            "arm": self.arm,
            "reachable_share": self.reachable_share,
            "base": list(self.base),
            "object_size": self.object_size,
            "candidates": self.candidates,
            "reachable": self.reachable,
            "per_parallel": [
                {"elevation_deg": e, "reachable": r, "views": n, "share": r / n if n else 0.0}
                for e, r, n in self.per_parallel
            ],
            "reasons": dict(self.reasons),
            "searched": [{"distance": d, "height": h, "share": s} for d, h, s in self.searched],
        }


def object_box(size: float) -> BoundingBox:
    """The box of an object of ``size`` metres standing on the plate, centred on its axis (table frame)."""
    if not (math.isfinite(size) and size > 0):
        raise ValueError(f"object size: must be > 0 metres, got {size!r}")
    h = 0.5 * size
    return BoundingBox(np.array([-h, -h, 0.0]), np.array([h, h, size]))


def hemisphere(size: float, planner: PlannerConfig | None = None, count: int | None = None) -> tuple[Candidate, ...]:
    """The planner's candidate hemisphere about :func:`object_box` (``count`` views, else the config's)."""
    config = planner or PlannerConfig()
    if count is not None:
        config = config.replace(candidates={"count": count})
    candidates, _, _ = propose_candidates(object_box(size), config.candidates, config.partitions)
    return candidates


def hemisphere_reachability(
    kinematics: Any, candidates: tuple[Candidate, ...], size_box: BoundingBox | None, q: Any, angle: float
) -> list[tuple[bool, str | None]]:
    """(reachable, reason) of each candidate for ``kinematics`` (an ``ArmKinematics``) from the state (``q`` (n,),
    plate ``angle``), with ``size_box`` (table frame) as the object it keeps clear of."""
    if size_box is None:
        kinematics.set_object_box(None, None)
    else:
        kinematics.set_object_box(size_box.lower, size_box.upper)
    return [kinematics.reachability(c.T_world_camera, q, angle) for c in candidates]


def reach_report(
    arm: ArmConfig,
    size: float = 0.2,
    *,
    base: tuple[float, float, float] | None = None,
    planner: PlannerConfig | None = None,
    cell: CellConfig | None = None,
    count: int | None = None,
) -> ReachReport:
    """The share of the candidate hemisphere (``count`` views, else the planner config's) the arm reaches from
    ``base`` (else its configured mount), from its home with the plate at 0, for an object of ``size`` metres."""
    from devices.arm.kinematics import ArmKinematics

    cell = cell or CellConfig()
    if base is not None:
        arm = dataclasses.replace(arm, base=tuple(float(v) for v in base))
    kinematics = ArmKinematics(arm, cell.plate_radius, cell.plate_thickness)
    candidates = hemisphere(size, planner, count)
    results = hemisphere_reachability(kinematics, candidates, object_box(size), kinematics.home, 0.0)
    per: dict[int, list[int]] = {}
    elevation: dict[int, float] = {}
    reasons: Counter[str] = Counter()
    for c, (ok, reason) in zip(candidates, results, strict=True):
        counts = per.setdefault(c.parallel, [0, 0])
        counts[0] += int(ok)
        counts[1] += 1
        elevation[c.parallel] = math.degrees(c.elevation)
        if not ok:
            reasons[reason or "unreachable"] += 1
    return ReachReport(
        arm=arm.urdf,
        base=arm.mount,
        object_size=size,
        candidates=len(candidates),
        reachable=sum(int(ok) for ok, _ in results),
        per_parallel=tuple(
            (round(elevation[p], 2), per[p][0], per[p][1]) for p in sorted(per, key=lambda p: elevation[p])
        ),
        reasons=dict(reasons.most_common()),
    )


def search_mount(
    arm: ArmConfig,
    size: float = 0.2,
    *,
    planner: PlannerConfig | None = None,
    cell: CellConfig | None = None,
    count: int | None = None,
    distances: tuple[float, ...] | None = None,
    heights: tuple[float, ...] | None = None,
) -> ReachReport:
    """The mount on the -x side of the plate (distance from the axis x height, the preset's ``cell_scale`` times
    :data:`SEARCH_DISTANCES` x :data:`SEARCH_HEIGHTS` unless given) whose coarse hemisphere
    (:data:`SEARCH_CANDIDATES` views) has the largest reachable share (ties: the nearer, then the lower), reported
    on the full hemisphere with every mount tried in ``searched``."""
    cell = cell or CellConfig()
    scale = arm.defaults.cell_scale
    distances = distances or tuple(round(d * scale, 3) for d in SEARCH_DISTANCES)
    heights = heights or tuple(round(h * scale, 3) for h in SEARCH_HEIGHTS)
    tried: list[tuple[float, float, float]] = []
    for d in distances:
        if d <= cell.plate_radius:
            continue
        for h in heights:
            if h < arm.table_height:
                continue
            report = reach_report(arm, size, base=(-d, 0.0, h), planner=planner, cell=cell, count=SEARCH_CANDIDATES)
            tried.append((d, h, report.reachable_share))
    if not tried:
        raise ValueError(f"mount search: every distance is inside the plate (radius {cell.plate_radius} m)")
    d, h, _ = max(tried, key=lambda t: (round(t[2], 6), -t[0], -t[1]))
    best = reach_report(arm, size, base=(-d, 0.0, h), planner=planner, cell=cell, count=count)
    return dataclasses.replace(best, searched=tuple(tried))
