"""The arm of one session in its tabs' 3D views: where it is, where the selected view would take it, and why an
unreachable candidate is unreachable.

One :class:`SessionArm` per session (shared by the session's viewers) plans the move to the selected target once
per selection (``Cell.plan_motion``: the ghost's joint target and the camera's path) and works out, lazily once
per plan, the cell's reason for each candidate the planner found unreachable (``no_ik``, ``joint_limit``,
``collision:<link>:<obstacle>``). Each viewer's :class:`app.scene.robot.RobotScene` draws it under ``/robot``.
The URDF with its meshes is loaded once per arm model and shared by every tab.
"""

from __future__ import annotations

import threading
from dataclasses import dataclass
from typing import Any

import numpy as np

from app.scene.robot import RobotScene, load_urdf_for_viser
from devices.arm.model import ArmModel
from devices.cell import Motion
from devices.protocols import UnreachableError
from planner import PlanResult, Pose
from workbench import BUSY, SceneData

_URDFS: dict[int, Any] = {}
_URDF_LOCK = threading.Lock()


def shared_urdf(arm: ArmModel) -> Any:
    """The ``yourdfpy.URDF`` of ``arm`` with its meshes, loaded once per model (every tab draws from it)."""
    with _URDF_LOCK:
        urdf = _URDFS.get(id(arm))
        if urdf is None:
            urdf = _URDFS[id(arm)] = load_urdf_for_viser(arm)
        return urdf


@dataclass(frozen=True, eq=False)
class ArmTarget:
    """The move to the selected view: ``motion`` when reachable, else None and the cell's ``reason``.

    key: what was selected (plan id and candidate index, or the custom pose's position); kind: 'candidate' or
    'custom'; index: the candidate (None for a custom pose).
    """

    key: tuple[Any, ...]
    kind: str
    index: int | None
    motion: Motion | None
    reason: str | None

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


class SessionArm:
    """The arm of session ``session`` (whose cell has kinematics): the move to the selection, unreachable reasons."""

    def __init__(self, session: Any) -> None:
        self.session = session
        self.cell = session.cell
        if self.cell.kinematics is None:
            raise ValueError(f"session {session.id}: its cell has no arm model (kinematics)")
        self.model: ArmModel = self.cell.kinematics.model
        self._lock = threading.Lock()
        self._target: ArmTarget | None = None
        self._reasons_of: PlanResult | None = None
        self._reasons: dict[int, str] = {}
        self.animated_motion: Motion | None = None
        """The last executed motion already animated in the views (each is animated once)."""

    def new_scene(self, client: Any) -> RobotScene:
        """A RobotScene of this arm in ``client``'s scene, at the cell's current joints and plate angle."""
        robot = RobotScene(client, self.model, urdf=shared_urdf(self.model))
        robot.show(self.cell.arm.joint_positions(), self.cell.angle)
        return robot

    def target(self, data: SceneData) -> ArmTarget | None:
        """The move to the selected target of ``data`` (planned once per selection); None without a plan, and
        None while the session is busy (moving, planning, auto) unless it was planned already: the arm's
        kinematics are the session's then."""
        sel = selected_target(data)
        if sel is None:
            return None
        key, kind, index, pose = sel
        with self._lock:
            if self._target is not None and self._target.key == key:
                return self._target
            if self.session.state in BUSY:
                return None
            then = [] if kind == "custom" or data.plan is None else data.plan.then_poses(index)
            try:  # the move the approve will make (planned for the views the tour expects next, if any)
                motion, reason = self.cell.plan_motion(pose, then=then), None
            except UnreachableError as exc:
                motion, reason = None, str(exc)
            if motion is not None and (motion.q is None or motion.trajectory is None):
                motion, reason = None, "the arm gave no joint target"
            self._target = ArmTarget(key, kind, index, motion, reason)
            return self._target

    def unreachable_reasons(self, plan: PlanResult) -> dict[int, str]:
        """{candidate index: the cell's reason} for the candidates ``plan`` found unreachable (computed once per
        plan, in candidate order so that neighbours warm-start each other's IK; {} while the session is busy)."""
        with self._lock:
            if self._reasons_of is plan:
                return dict(self._reasons)
            if self.session.state in BUSY:
                return {}
            reasons = plan.ineligible_reasons
            indices = [i for i, r in enumerate(reasons) if r == "unreachable"]
            checks = self.cell.reachability_many([plan.candidates[i].T_world_camera for i in indices])
            self._reasons = {i: (why or "unreachable") for i, (ok, why) in zip(indices, checks, strict=True) if not ok}
            for i, (ok, _) in zip(indices, checks, strict=True):
                if ok:  # reachable now (the arm moved since the plan): the plan's verdict stands
                    self._reasons[i] = "unreachable"
            self._reasons_of = plan
            return dict(self._reasons)

    def show_target(self, robot: RobotScene, target: ArmTarget | None) -> None:
        """The ghost at the target's joints and the camera's path, or neither (no target, or unreachable)."""
        if target is None or target.motion is None or target.motion.q is None:
            robot.show_ghost(None)
            robot.show_path(None)
            return
        robot.show_ghost(target.motion.q, target.motion.angle)
        robot.show_path(target.motion.trajectory, target.motion.angle)

    def after_capture(self, robot: RobotScene) -> None:
        """The arm at its new configuration: the executed trajectory animated if the cell kept it, else a jump."""
        robot.show_ghost(None)
        robot.show_path(None)
        motion = self.cell.last_motion
        q_now = self.cell.arm.joint_positions()
        if motion is not None and motion.trajectory is not None and np.allclose(motion.trajectory.positions[-1], q_now):
            robot.animate(motion.trajectory, motion.angle)
        else:
            robot.stop()
            robot.show(q_now, self.cell.angle)
