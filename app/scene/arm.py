"""The arm of one session in its tabs' 3D views: where it is, where the selected view would take it, and why an
unreachable candidate is unreachable.

One :class:`SessionArm` per session (shared by the session's viewers) shows the move to the selected target
(:class:`app.scene.movetarget.SessionMoves`, planned once per selection under the session's lock: the ghost's
joint target and the camera's path) and works out, lazily once
per plan, the cell's reason for each candidate the planner found unreachable (``no_ik``, ``joint_limit``,
``collision:<link>:<obstacle>``). Each viewer's :class:`app.scene.robot.RobotScene` draws it under ``/robot``.
The URDF with its meshes is loaded once per arm model and shared by every tab.
"""

from __future__ import annotations

import threading
from typing import Any

import numpy as np

from app.scene.movetarget import ArmTarget, SessionMoves, selected_target
from app.scene.robot import RobotScene, load_urdf_for_viser
from devices.arm.model import ArmModel
from devices.cell import Motion
from planner import PlanResult
from workbench import BUSY, SceneData

__all__ = ["ArmTarget", "SessionArm", "selected_target", "shared_urdf"]

_URDFS: dict[int, Any] = {}
_URDF_LOCK = threading.Lock()


def shared_urdf(arm: ArmModel) -> Any:
    """The ``yourdfpy.URDF`` of ``arm`` with its meshes, loaded once per model (every tab draws from it)."""
    with _URDF_LOCK:
        urdf = _URDFS.get(id(arm))
        if urdf is None:
            urdf = _URDFS[id(arm)] = load_urdf_for_viser(arm)
        return urdf


class SessionArm:
    """The arm of session ``session`` (whose cell has kinematics): the move to the selection, unreachable reasons."""

    def __init__(self, session: Any, moves: SessionMoves | None = None) -> None:
        self.session = session
        self.moves = moves if moves is not None and moves.session is session else SessionMoves(session)
        """The move to the selection (shared with the session's ``path`` layer)."""
        self.cell = session.cell
        if self.cell.kinematics is None:
            raise ValueError(f"session {session.id}: its cell has no arm model (kinematics)")
        self.model: ArmModel = self.cell.kinematics.model
        self._lock = threading.Lock()
        self._reasons_of: PlanResult | None = None
        self._reasons: dict[int, str] = {}
        self.animated_motion: Motion | None = None
        """The last executed motion already animated in the views (each is animated once)."""

    def new_scene(self, client: Any) -> RobotScene:
        """A RobotScene of this arm in ``client``'s scene, at the cell's current joints and plate angle."""
        robot = RobotScene(client, self.model, urdf=shared_urdf(self.model))
        robot.show(self.cell.arm.joint_positions(), self.cell.angle)
        return robot

    def target(self, data: SceneData | None = None) -> ArmTarget | None:
        """The move to the session's selected target (``SessionMoves.target``: planned once per selection under the
        session's lock); None without a plan, and None while the session is busy unless it was planned already.
        data: ignored (the selection is read under the lock)."""
        return self.moves.target()

    def unreachable_reasons(self, plan: PlanResult) -> dict[int, str]:
        """{candidate index: the cell's reason} for the candidates ``plan`` found unreachable (computed once per
        plan, in candidate order so that neighbours warm-start each other's IK; {} while the session is busy). The
        cell is asked under the session's lock (then ours, the order :class:`SessionMoves` takes): no action uses it
        meanwhile."""
        with self.session.lock, self._lock:
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
