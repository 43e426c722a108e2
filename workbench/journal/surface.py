"""A session's surface rebuilt from its journal: the kept captures' frames fused at their journaled poses.

The ``capture`` events left after discards (workbench/journal/discard.py), in order, each frame at its
``pose_used`` (the registered pose the live surface fused), after the frames kept from the move to it: the same surface as the live one, array for array.
"""

from __future__ import annotations

import logging
from pathlib import Path
from typing import Any

from devices.config import DeviceConfig
from planner import Pose
from planner.config import from_dict
from workbench.evaluation.accuracy import GroundTruth
from workbench.journal.discard import without_discarded
from workbench.journal.store import Journal, read_journal
from workbench.surface.config import SurfaceConfig, surface_config_for
from workbench.surface.live import LiveSurface, SurfaceUpdate

log = logging.getLogger(__name__)


def header_surface_config(header: dict[str, Any]) -> SurfaceConfig:
    """The surface settings of a session from its journal header: ``surface_config_for`` its camera (a real
    sensor's noise fuses with a tighter truncation, like ``nbv scan`` and ``nbv bench``); a header without a
    readable camera: the defaults."""
    try:
        devices = from_dict(DeviceConfig, header["devices"])
    except (KeyError, TypeError, ValueError):
        return SurfaceConfig()
    return surface_config_for(devices.camera)


def surface_of_journal(
    journal: Journal, truth: GroundTruth | None = None, config: SurfaceConfig | None = None
) -> LiveSurface:
    """The :class:`LiveSurface` of ``journal``'s kept captures (extracted once, at the end; scored against
    ``truth`` when given), with ``config`` (default: :func:`header_surface_config`). A frame that cannot be
    read is noted in the update's ``error`` like any surface failure, never raised."""
    live = LiveSurface(config if config is not None else header_surface_config(journal.header), truth=truth)
    captures = [ev for ev in without_discarded(journal.events) if ev.get("kind") == "capture"]
    error = None
    for ev in captures:
        try:
            frame, pose = journal.frame(ev), Pose.from_dict(ev["pose_used"])
            moves = journal.move_frames(ev)
        except (OSError, ValueError, KeyError) as exc:
            live.views += 1
            error = f"view {live.views}: the journal's frame cannot be read ({exc})"
            continue
        for move_frame, move_pose in moves:  # the frames of the move to the view come first, as in the session
            live.fuse_move_frame(move_frame, move_pose)
        live.add(frame, pose, extract=False)
    live.extract(0.0, error)
    return live


def in_step(
    live: LiveSurface | None, views: int, journal_dir: Path | None, truth: GroundTruth | None = None
) -> LiveSurface:
    """``live`` when it has followed the session's ``views`` views so far; else (a new worker process, a view
    that was not published) the surface rebuilt from the journal in ``journal_dir``, or an empty one that says
    what was lost when there is no journal."""
    if live is not None and live.views == views:
        return live
    if journal_dir is not None:
        try:
            return surface_of_journal(read_journal(journal_dir), truth)
        except (OSError, ValueError) as exc:
            log.warning("surface: cannot rebuild from the journal: %s", exc)
    fresh = LiveSurface(truth=truth)
    fresh.views = views
    if views:
        fresh.update = SurfaceUpdate(views, None, None, f"the surface of the first {views} view(s) was lost", 0.0)
    return fresh
