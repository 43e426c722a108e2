"""Which frames taken during a move go into the map, and integrating them (the session, the headless scan and the
bench share it).

The cell hands the frames of a move (:class:`devices.move_capture.MoveFrame`, stamps in seconds since the move
started). :func:`integrate_move_frames` takes them in stamp order through ``Planner.integrate(move_frame=True)``
(preprocessing, registration, voxel map) under three rules, measured in docs/experiments/move-capture.md:

- the rate: the cell took them at ``CellConfig.move_capture_hz``;
- new coverage: a frame whose points on the object lie almost all within a voxel of the map's occupied ones
  (less than ``move_capture_min_new`` of them new) is left out (:func:`new_share`, a cheap look-up);
- time: integration runs beside the move on a real cell (frame k can start at its stamp, or when frame k - 1 is
  done); a frame whose integration would end later than ``(1 + move_capture_wait)`` times the move's modelled
  duration (its start, plus the slowest integration of the move so far, or of the move before) is left out, so no move waits for
  integration by more than that share of its time (a frame slower than every earlier one may still overrun: the
  wait is reported). A simulated move is
  instant: the integration seconds are measured and accounted against the move's modelled duration
  (:class:`MoveIntegration` reports both). The seconds are the process's CPU seconds (``time.process_time``): what
  the integration costs, not how long a loaded machine made it wait, so a scan keeps the same frames on a busy
  machine as on an idle one (wall seconds on the shared 2-core host kept almost no frame at load 12-25).
"""

from __future__ import annotations

import copy
import math
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from devices.config import CellConfig
from devices.move_capture import MoveFrame
from planner import DepthFrame, Planner, Pose, VoxelClass
from planner.planner import IntegrationReport

NEW_SHARE_STRIDE = 4
""":func:`new_share` looks at every this-many-th pixel in both directions (1/16 of a frame's points)."""
PLATE_MARGIN = 0.005
"""Points lower than this above the plate top (z = 0) are the plate's, not the object's, metres."""


@dataclass(frozen=True)
class KeepRule:
    """Which move frames are integrated: ``min_new`` share of new points, ``wait`` share of the move's duration
    integration may outlast it by (``CellConfig.move_capture_min_new``, ``move_capture_wait``)."""

    min_new: float = 0.02
    wait: float = 0.1
    registered: bool = False
    """Keep a frame only when ICP accepted its pose (a frame ICP cannot confirm counts as rejected)."""
    max_speed: float = 0.0
    """Keep a frame only when its view moved slower than this at its stamp, m/s (``MoveFrame.speed``; 0: any)."""

    @classmethod
    def of(cls, cell: CellConfig) -> KeepRule:
        return cls(
            cell.move_capture_min_new, cell.move_capture_wait, cell.move_capture_registered, cell.move_capture_max_speed
        )


def new_share(planner: Planner, frame: DepthFrame, stride: int = NEW_SHARE_STRIDE) -> float:
    """The share of ``frame``'s points above the plate (every ``stride``-th pixel, at its reported pose) farther than
    one voxel from the map's occupied voxels (or outside its box): surface the map has not seen. 1.0 before the map
    has a box, 0.0 for a frame with no such point. (Without the one-voxel margin a view turned by a degree already
    looks 15-20 % new at 1 cm voxels: slivers of surface in voxels no earlier point fell into.)"""
    depth = frame.depth[::stride, ::stride]
    rows, cols = np.nonzero(depth > 0)
    if len(rows) == 0:
        return 0.0
    k = frame.intrinsics
    z = depth[rows, cols].astype(np.float64)
    x = (cols * stride - k.cx) / k.fx * z
    y = (rows * stride - k.cy) / k.fy * z
    points = frame.T_world_camera.apply(np.stack([x, y, z], axis=1))
    points = points[points[:, 2] > PLATE_MARGIN]
    if len(points) == 0:
        return 0.0
    voxel_map = planner.voxel_map
    if voxel_map.bbox is None:
        return 1.0
    idx = voxel_map.voxel_of(points)
    shape = np.array(voxel_map.shape)
    inside = np.all((idx >= 0) & (idx < shape), axis=1)
    from scipy.ndimage import binary_dilation

    classes = voxel_map.classes
    near = binary_dilation(classes == VoxelClass.OCCUPIED, np.ones((3, 3, 3), dtype=bool))
    seen = np.zeros(len(points), dtype=bool)
    ii = idx[inside]
    seen[inside] = near[ii[:, 0], ii[:, 1], ii[:, 2]]
    return float(np.count_nonzero(~seen)) / len(points)


@dataclass(frozen=True)
class KeptFrame:
    """A move frame that went into the map: the frame as captured (reported pose), its stamp, the registered pose
    the map used, its points after preprocessing and its share of new points."""

    frame: DepthFrame
    t: float
    T_world_camera: Pose
    points_frame: int
    new_share: float


@dataclass
class MoveIntegration:
    """What became of one move's frames."""

    move_seconds: float
    """The move's modelled duration, seconds."""
    taken: int = 0
    kept: list[KeptFrame] = field(default_factory=list)
    seen: int = 0
    """Left out: too little new (``min_new``)."""
    fast: int = 0
    """Left out: taken while the view moved faster than ``max_speed``."""
    late: int = 0
    """Left out: integration would have outlasted the move by more than ``wait`` of its duration."""
    rejected: int = 0
    """The planner could not use them (nothing on the object)."""
    integration_seconds: float = 0.0
    """CPU seconds spent on the move's frames (the new-share look-ups and the integrations; the ``clock``)."""
    wait_seconds: float = 0.0
    """How long a real move would wait for its frames' integration at its end (stamps + measured seconds)."""
    slowest: float = 0.0
    """The slowest integration of a kept frame, seconds (the next move's first estimate)."""

    def to_json(self) -> dict[str, Any]:
        """The ``move_capture`` block of a view (journal, metrics)."""
        return {
            "move_seconds": self.move_seconds,
            "taken": self.taken,
            "kept": len(self.kept),
            "seen": self.seen,
            "fast": self.fast,
            "late": self.late,
            "rejected": self.rejected,
            "integration_seconds": self.integration_seconds,
            "wait_seconds": self.wait_seconds,
        }


def integrate_move_frames(
    planner: Planner,
    frames: Sequence[MoveFrame],
    move_seconds: float,
    rule: KeepRule,
    on_kept: Callable[[KeptFrame], None] | None = None,
    clock: Callable[[], float] = time.process_time,
    prior: float = 0.0,
) -> MoveIntegration:
    """Integrate the frames of one move (``move_seconds`` long) into ``planner`` in stamp order under ``rule``;
    ``on_kept`` hears each frame that went in (e.g. the surface, the coverage at its stamp). prior: the seconds one
    integration is expected to take before this move's first (the previous move's ``slowest``)."""
    out = MoveIntegration(float(move_seconds), taken=len(frames))
    limit = (1.0 + rule.wait) * move_seconds
    finish = 0.0
    costs: list[float] = []
    for mf in sorted(frames, key=lambda f: f.t):
        if rule.max_speed > 0 and mf.speed is not None and mf.speed > rule.max_speed:
            out.fast += 1
            continue
        start = max(mf.t, finish)
        estimate = max(costs, default=prior)  # the slowest so far: a loaded machine's spikes are kept in the bound
        if start + estimate > limit:
            out.late += 1
            continue
        t0 = clock()
        share = new_share(planner, mf.frame)
        kept = None
        if share < rule.min_new:
            out.seen += 1
        else:
            try:
                report = planner.integrate(mf.frame, move_frame=True, registered=rule.registered)
            except ValueError:
                out.rejected += 1
            else:
                kept = KeptFrame(mf.frame, mf.t, report.T_world_camera, report.n_points_frame, share)
        cost = clock() - t0
        if kept is not None:
            costs.append(cost)
            out.kept.append(kept)
            if on_kept is not None:
                on_kept(kept)
        finish = start + cost
        out.integration_seconds += cost
    out.wait_seconds = max(0.0, finish - move_seconds) if math.isfinite(finish) else 0.0
    out.slowest = max(costs, default=prior)
    return out


Moving = tuple[list[MoveFrame], float, KeepRule, float]
"""The frames of a move, its modelled seconds, the keep rule, the prior estimate of one integration's seconds."""


def integrate_step(
    planner: Planner, frame: DepthFrame, moving: Moving | None
) -> tuple[IntegrationReport, Planner, MoveIntegration | None]:
    """Integrate one view into ``planner`` (the session's, or a worker's copy): first the frames of the move to it
    (``moving``: the frames, the move's modelled seconds, the keep rule, the prior; :func:`integrate_move_frames`), then the
    view. Atomic: with move frames the work is done on a copy, so a ValueError of the view leaves ``planner`` as it
    was. Returns (report, the planner after the view, what became of the frames)."""
    if moving is None:
        return planner.integrate(frame), planner, None
    frames, move_seconds, rule, prior = moving
    work = copy.deepcopy(planner)
    moves = integrate_move_frames(work, frames, move_seconds, rule, prior=prior)
    return work.integrate(frame), work, moves
