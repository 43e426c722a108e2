"""The page previews the move an approve makes: for the tour ring's first view, the move planned for the views named
after it (``PlanResult.then_poses``), not the plain shortest one."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from app.scene.arm import SessionArm
from workbench import SessionRegistry, WorkbenchSettings


def test_the_arm_preview_is_the_move_the_approve_makes(tmp_path: Path) -> None:
    registry = SessionRegistry(WorkbenchSettings(data_dir=tmp_path, workers=False))
    try:
        session = registry.create(model="sphere", config={"voxel": {"resolution": 0.02}}, seed=0, planner="tour")
        session.capture()
        entry = session.plan()
        best = entry.plan.best_index
        assert best is not None and entry.plan.then_poses(best)
        preview = SessionArm(session).target(session.scene_data())
        assert preview is not None and preview.motion is not None and preview.index == best
        plain = session.cell.plan_motion(entry.plan.candidates[best].T_world_camera)
        assert not np.allclose(preview.motion.q, plain.q)  # the look-ahead's target, not the shortest move's
        session.approve(entry.plan_id, best)
        moved = session.cell.last_motion
        assert moved is not None and np.allclose(moved.q, preview.motion.q)
        assert moved.duration == preview.motion.duration
    finally:
        registry.close()
