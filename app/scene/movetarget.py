"""The move to a session's selected view, as the page previews it: planned once per selection, under the session's
lock while it rests, never on viser's event thread.

:class:`SessionMoves` (one per session, whatever its cell: a URDF arm or the reach sphere) asks the cell for the
motion an approval would run to the selected view (``Cell.plan_motion``, with the views the plan's tour expects
next) and, in the same hold of the session's lock, where the camera starts from (:class:`MovePath`): the ghost arm
(app/scene/arm.py) shows the motion's joint target and the ``path`` layer (app/scene/pathlayer.py) the camera
frustums along the way. Holding the lock keeps the cell to this question alone: an action cannot claim the session
(and move the arm) between the check that it rests and the answer, and the approval that follows plans its own
move after this one ended.
"""

from __future__ import annotations

import threading
from dataclasses import dataclass
from typing import Any

import numpy as np

from devices.cell import Motion
from devices.move_capture import MovePath
from devices.protocols import UnreachableError
from planner import Pose
from workbench import BUSY, SceneData


@dataclass(frozen=True, eq=False)
class ArmTarget:
    """The move to the selected view: ``motion`` when reachable, else None and the cell's ``reason``.

    key: what was selected (plan id and candidate index, or the custom pose's position); kind: 'candidate' or
    'custom'; index: the candidate (None for a custom pose); path: where the camera goes during the move, from the
    cell's state when it was planned (None when unreachable, or for a cell whose moves are not timed: a replay).
    """

    key: tuple[Any, ...]
    kind: str
    index: int | None
    motion: Motion | None
    reason: str | None
    path: MovePath | None = None

    def to_json(self) -> dict[str, Any]:
        m = self.motion
        return {
            "kind": self.kind,
            "index": self.index,
            "reachable": m is not None,
            "reason": self.reason,
            "joints": None if m is None or m.q is None else [float(v) for v in m.q],
            "plate_angle": None if m is None else float(m.angle),
            "duration": None if m is None else float(m.duration),
            "path_method": None if m is None else (m.path_method or None),
        }


def selected_target(data: SceneData) -> tuple[tuple[Any, ...], str, int | None, Pose] | None:
    """(key, kind, index, T_table_camera) of what a tab shows as selected: the custom pose, else the selected
    candidate, else the planner's choice; None without a pending plan."""
    plan = data.plan
    if plan is None or data.plan_id is None:
        return None
    if data.custom is not None:
        pose = data.custom.pose
        key = (data.plan_id, "custom", *np.round(pose.translation, 6), *np.round(pose.rotation.ravel(), 6))
        return key, "custom", None, pose
    index = data.selected if data.selected is not None else plan.best_index
    if index is None or not 0 <= index < len(plan.candidates):
        return None
    return (data.plan_id, "candidate", index), "candidate", index, plan.candidates[index].T_world_camera


class SessionMoves:
    """The move to the selected view of ``session``, planned once per selection (its plan id and candidate, or the
    custom pose)."""

    def __init__(self, session: Any) -> None:
        self.session = session
        self._lock = threading.Lock()
        self._target: ArmTarget | None = None

    def current(self) -> ArmTarget | None:
        """The move to the selection as planned already; None when the selection has none yet (nothing planned)."""
        sel = selected_target(self.session.scene_data())
        with self._lock:
            target = self._target
        return target if sel is not None and target is not None and target.key == sel[0] else None

    def target(self) -> ArmTarget | None:
        """The move to the session's selection now: planned once per selection, under the session's lock (a REST
        request's or a scene worker's thread: it may take a motion planner's time). None without a pending plan,
        and None while the session is busy (moving, planning, auto) unless it was planned already: the arm and
        the plate are the action's then."""
        with self.session.lock:  # first the session's, then ours: the order every caller takes
            sel = selected_target(self.session.scene_data())
            if sel is None:
                return None
            key, kind, index, pose = sel
            with self._lock:
                if self._target is not None and self._target.key == key:
                    return self._target
                if self.session.state in BUSY:
                    return None
                self._target = self._plan(key, kind, index, pose)
                return self._target

    def _plan(self, key: tuple[Any, ...], kind: str, index: int | None, pose: Pose) -> ArmTarget:
        """Ask the cell (the caller holds the session's lock, the session resting)."""
        cell = self.session.cell
        plan = self.session.scene_data().plan
        then = [] if kind == "custom" or plan is None else plan.then_poses(index)
        try:  # the move the approve will make (planned for the views the tour expects next, if any)
            motion, reason = cell.plan_motion(pose, then=then), None
        except UnreachableError as exc:
            motion, reason = None, str(exc)
        if motion is not None and cell.kinematics is not None and (motion.q is None or motion.trajectory is None):
            motion, reason = None, "the arm gave no joint target"
        path = None if motion is None or not motion.timed else MovePath.of(cell, motion)
        return ArmTarget(key, kind, index, motion, reason, path)
