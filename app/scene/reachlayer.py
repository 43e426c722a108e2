"""The ``reach`` layer: the session's candidate hemisphere coloured by what its arm can reach.

The hemisphere is the current plan's candidates, or before a plan the planner's default hemisphere about the
object's box (``propose_candidates`` of the voxel map's box, as ``nbv arms check`` builds it about an object of a
size). Each view is asked of the session's own cell (``Cell.reachability_many``: the IK, joint limits, collision
model and the plate's turn the planner uses, with the cell's reachability cache), so the layer shows the planner's
verdicts, never those of a second model. A reach-sphere cell answers ``reach`` for a view outside its sphere.

The answers are computed once per plan (or per box before a plan) and per session, on a thread of their own (the
page's request and the session's events never wait for them), a chunk at a time under the session's lock while it
rests (never beside an action using the cell), and only while some tab shows the layer: a plan in a session no tab
shows the layer of costs nothing more.
"""

from __future__ import annotations

import logging
import threading
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

import numpy as np
from numpy.typing import NDArray

from devices.arm.mount import object_box
from planner.candidates import propose_candidates
from planner.types import BoundingBox
from workbench import BUSY

log = logging.getLogger(__name__)

CHUNK = 25
"""Views asked of the cell per hold of the session's lock (a status read waits for one chunk at most: about 0.1 s
for the UR5 on a loaded 2-core machine, none for a plan's views, which the cell has cached)."""

REACH_CLASSES: dict[str, tuple[str, tuple[int, int, int]]] = {
    "reachable": ("reachable", (0, 170, 70)),
    "no_ik": ("no IK solution", (220, 30, 30)),
    "joint_limit": ("joint limits", (245, 150, 0)),
    "collision": ("collision", (150, 40, 190)),
    "turn": ("the plate's turn", (0, 120, 230)),
    "reach": ("outside the reach sphere", (120, 120, 120)),
    "other": ("other", (40, 40, 40)),
}
"""Class -> (legend label, colour) of the reach layer's points, in the legend's order."""


def reach_class(reachable: bool, reason: str | None) -> str:
    """The layer's class of a cell answer (``reachable``, reason): a key of :data:`REACH_CLASSES`."""
    if reachable:
        return "reachable"
    why = reason or ""
    if why.startswith("turn:"):
        return "turn"
    if why.startswith("collision"):
        return "collision"
    if why in ("no_ik", "joint_limit", "reach"):
        return why
    return "other"


@dataclass(frozen=True, eq=False)
class ReachMap:
    """The hemisphere's views and their classes: what the ``reach`` layer draws.

    key: what it was computed for (the plan object, or ``("box", lower, upper)`` before a plan); positions:
    (N, 3) float32 camera positions, table frame; classes: N keys of :data:`REACH_CLASSES`.
    """

    key: Any
    positions: NDArray[np.float32]
    classes: tuple[str, ...]
    spacing: float
    """Metres: the mean distance between neighbouring views (the points' size follows it)."""

    @property
    def colors(self) -> NDArray[np.uint8]:
        """(N, 3) uint8: each view's class colour."""
        if not self.classes:
            return np.zeros((0, 3), dtype=np.uint8)
        return np.array([REACH_CLASSES[c][1] for c in self.classes], dtype=np.uint8)

    def legend(self) -> list[dict[str, Any]]:
        """The classes present, in legend order: {class, label, color, count}."""
        counts = {c: self.classes.count(c) for c in set(self.classes)}
        return [
            {"class": c, "label": label, "color": list(rgb), "count": counts[c]}
            for c, (label, rgb) in REACH_CLASSES.items()
            if c in counts
        ]


DEFAULT_OBJECT_SIZE = 0.2
"""Metres: the object's size before the first view when the session has no ground truth (a real cell): the box of
``nbv arms check``'s default ``--object-size``."""


def object_box_of(session: Any) -> BoundingBox:
    """The object's box (table frame) the hemisphere is built about before a plan: the voxel map's box once a view
    was taken, else the ground-truth mesh's bounds (a simulated cell), else :func:`devices.arm.mount.object_box`
    of :data:`DEFAULT_OBJECT_SIZE` (what ``nbv arms check`` asks about)."""
    box = session.planner.voxel_map.bbox
    if box is not None:
        return box
    mesh = session.scene_data().mesh
    if len(mesh.faces):
        lower, upper = np.asarray(mesh.bounds, dtype=np.float64)
        return BoundingBox(lower, upper)
    return object_box(DEFAULT_OBJECT_SIZE)


def hemisphere_key(session: Any, plan: Any) -> Any:
    """What ``session``'s reach map is computed for: ``plan`` (its current plan), else the object's box
    (:func:`object_box_of`) as ``("box", lower, upper)``."""
    if plan is not None:
        return plan
    box = object_box_of(session)
    return ("box", tuple(float(v) for v in box.lower), tuple(float(v) for v in box.upper))


def hemisphere_of(session: Any) -> tuple[Any, tuple[Any, ...], BoundingBox, float]:
    """(key, candidates, the object's box, hemisphere radius) of ``session``: its plan's, else the planner's
    default hemisphere about the object's box (:func:`object_box_of`)."""
    plan = session.scene_data().plan
    if plan is not None:
        return plan, tuple(plan.candidates), plan.bbox, float(plan.hemisphere_radius)
    box = object_box_of(session)
    key = ("box", tuple(float(v) for v in box.lower), tuple(float(v) for v in box.upper))
    config = session.config
    candidates, _, radius = propose_candidates(box, config.candidates, config.partitions)
    return key, candidates, box, float(radius)


def compute_reach_map(session: Any) -> ReachMap | None:
    """The reach map of ``session`` now, from its cell's answers; None when the session is busy or its hemisphere
    changed before all were in.

    The cell is asked :data:`CHUNK` views at a time under the session's lock, the session resting: no action claims
    the session (and its cell) meanwhile, and an action between two chunks (a busy state, or a new plan, view or
    box) ends the computation (the next plan or view asks again)."""
    with session.lock:
        if session.state in BUSY:
            return None
        key, candidates, box, radius = hemisphere_of(session)
        stamp = (len(session.scene_data().views), key)
    poses = [c.T_world_camera for c in candidates]
    answers: list[tuple[bool, str | None]] = []
    for start in range(0, len(poses), CHUNK):
        with session.lock:
            data = session.scene_data()
            if session.state in BUSY or not _same_stamp((len(data.views), hemisphere_key(session, data.plan)), stamp):
                return None
            chunk = poses[start : start + CHUNK]
            if data.plan is not None:  # the cell keeps the box the plan set
                answers += session.cell.reachability_many(chunk)
            else:  # before the first plan no box is set: the first plan's, for these answers only
                session.cell.set_object_box(box)
                try:
                    answers += session.cell.reachability_many(chunk)
                finally:
                    session.cell.set_object_box(None)
    n = len(candidates)
    positions = (
        np.stack([c.position for c in candidates]).astype(np.float32) if n else np.zeros((0, 3), dtype=np.float32)
    )
    spacing = float(np.sqrt(2.0 * np.pi * radius**2 / n)) if n else 0.0
    return ReachMap(key, positions, tuple(reach_class(ok, why) for ok, why in answers), spacing)


class ReachMaps:
    """The reach maps of the sessions, one per session, computed on a background thread when asked for.

    ``on_ready(session_id, reach_map)`` is called (on that thread) when a map is ready.
    """

    def __init__(self, on_ready: Callable[[str, ReachMap], None]) -> None:
        self._on_ready = on_ready
        self._lock = threading.Lock()
        self._maps: dict[str, ReachMap] = {}
        self._running: set[str] = set()

    def current(self, session: Any, plan: Any) -> ReachMap | None:
        """The session's map if it is up to date with ``plan`` (its current plan; None: its box), else None."""
        with self._lock:
            m = self._maps.get(session.id)
        if m is None:
            return None
        return m if _same_key(hemisphere_key(session, plan), m.key) else None

    def request(self, session: Any, plan: Any) -> ReachMap | None:
        """The session's map up to date with ``plan`` (its current plan, or None), or None while one is computed
        (started now on a thread if none runs)."""
        m = self.current(session, plan)
        if m is not None:
            return m
        with self._lock:
            if session.id in self._running:
                return None
            self._running.add(session.id)
        threading.Thread(target=self._compute, args=(session,), name=f"reach-{session.id}", daemon=True).start()
        return None

    def forget(self, session_id: str) -> None:
        with self._lock:
            self._maps.pop(session_id, None)

    def _compute(self, session: Any) -> None:
        try:
            m = compute_reach_map(session)
        except Exception:  # a map is a view of the cell: it never breaks the scene
            log.exception("reach layer of session %s failed", session.id)
            m = None
        finally:
            with self._lock:
                self._running.discard(session.id)
        if m is None:
            return
        with self._lock:
            self._maps[session.id] = m
        self._on_ready(session.id, m)


def _same_stamp(a: tuple[int, Any], b: tuple[int, Any]) -> bool:
    return a[0] == b[0] and _same_key(a[1], b[1])


def _same_key(a: Any, b: Any) -> bool:
    if isinstance(a, tuple) or isinstance(b, tuple):
        return a == b
    return a is b
