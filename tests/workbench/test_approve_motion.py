"""An approval plans its move once: the motion planned to check the target is the one the cell runs, and the arm
ends at that motion's configuration, the approved view."""

from __future__ import annotations

from typing import Any

import numpy as np
import pytest

from devices.cell import Motion, rz
from planner import Pose
from tests.helpers import SMALL
from workbench.errors import Unreachable
from workbench.registry.registry import SessionRegistry


def count_plans(monkeypatch: pytest.MonkeyPatch, kinematics: Any) -> list[Pose]:
    """The target of every call of the arm model's motion planning (``ArmKinematics.plan``), in order."""
    targets: list[Pose] = []
    plan = kinematics.plan

    def counted(T_table_camera: Pose, *args: Any, **kwargs: Any) -> Any:
        targets.append(T_table_camera)
        return plan(T_table_camera, *args, **kwargs)

    monkeypatch.setattr(kinematics, "plan", counted)
    return targets


def ends_at(session: Any, motion: Motion, target: Pose) -> None:
    """The arm is at ``motion``'s joints and plate angle, and the camera there sees ``target``."""
    cell = session.cell
    q = cell.joint_positions()
    assert motion.q is not None and np.allclose(q, motion.q, atol=1e-9)
    assert cell.angle == pytest.approx(motion.angle, abs=1e-9)
    T_table_camera = rz(-cell.angle) @ cell.kinematics.camera_pose(q)
    assert np.linalg.norm(T_table_camera.translation - target.translation) < 1e-4
    assert np.allclose(T_table_camera.rotation, target.rotation, atol=1e-3)


def test_an_approve_plans_the_move_once_and_runs_that_motion(
    registry: SessionRegistry, monkeypatch: pytest.MonkeyPatch
) -> None:
    session = registry.create("l-block", SMALL, seed=1)
    assert session.cell.kinematics is not None  # the UR5 cell
    session.capture()
    entry = session.plan()
    best = entry.plan.best_index
    assert best is not None
    target = entry.plan.candidates[best].T_world_camera
    planned = count_plans(monkeypatch, session.cell.kinematics)
    session.approve(entry.plan_id, index=best)
    assert len(planned) == 1 and np.allclose(planned[0].matrix, target.matrix)
    moved = session.cell.last_motion
    assert moved is not None
    ends_at(session, moved, target)
    assert session.status()["moves"] == 2
    record = session.record.iterations[-1]
    assert record["move_seconds"] == pytest.approx(moved.duration)


def test_an_override_plans_the_move_once_and_a_refused_one_moves_nothing(
    registry: SessionRegistry, monkeypatch: pytest.MonkeyPatch
) -> None:
    session = registry.create("l-block", SMALL, seed=1)
    session.capture()
    entry = session.plan()
    other = next(c.index for c in entry.plan.scores if c.eligible and c.index != entry.plan.best_index)
    target = entry.plan.candidates[other].T_world_camera
    planned = count_plans(monkeypatch, session.cell.kinematics)
    q_before = session.cell.arm.joint_positions()
    with pytest.raises(Unreachable):
        session.approve(entry.plan_id, pose=Pose.look_at(np.array([0.0, 0.0, 3.0]), np.zeros(3)))
    assert len(planned) == 1  # the check planned it and refused it; nothing moved
    assert np.array_equal(session.cell.arm.joint_positions(), q_before) and session.status()["moves"] == 1
    planned.clear()
    session.approve(entry.plan_id, index=other)
    assert len(planned) == 1
    moved = session.cell.last_motion
    assert moved is not None
    ends_at(session, moved, target)
