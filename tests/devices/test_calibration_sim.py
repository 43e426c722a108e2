"""The calibration routine on a simulated cell: the UR5 visits the poses, the D435 model sees the spheres, the
recovered hand-eye transform and turntable axis match the drawn truth (within 1 mm and 0.2 degrees)."""

from __future__ import annotations

import numpy as np
import pytest

from devices.calibration import (
    DEFAULT_TARGET,
    Calibration,
    CalibrationError,
    CalibrationPose,
    calibration_sim_cell,
    compare,
    sim_truth,
)
from planner.types import Pose


@pytest.fixture(scope="module")
def routine() -> Calibration:
    return Calibration(calibration_sim_cell("realsense-d435", "poor", seed=0))


def test_poses_are_listed_before_anything_moves(routine: Calibration) -> None:
    assert len(routine.poses) == 36 and len({p.label for p in routine.poses}) == 36
    assert routine.captures == []
    angles = {round(float(np.degrees(p.plate_angle))) for p in routine.poses}
    assert angles == {0, 60, 120, 180, -120, -60}
    q, plate = routine.cell.arm.joint_positions().copy(), routine.cell.angle
    motion = routine.preview(0)  # a plan, not a move
    assert abs(motion.angle - routine.poses[0].plate_angle) < 1e-9 and motion.trajectory is not None
    assert np.array_equal(routine.cell.arm.joint_positions(), q) and routine.cell.angle == plate
    # the plan reaches the pose: the camera at the asked pose at the asked plate angle
    assert np.allclose(motion.T_base_camera.matrix, routine.poses[0].T_base_camera.matrix, atol=1e-6)


@pytest.mark.slow
@pytest.mark.timeout(300)
def test_poor_calibration_seed_0_is_recovered_within_the_bounds(routine: Calibration) -> None:
    result = routine.run()
    assert routine.skipped == [] and len(routine.captures) == 36
    seen = [int(c.seen.sum()) for c in routine.captures]
    assert min(seen) >= 3 and seen.count(4) >= 24, seen  # a sphere may hide another from a low view
    out = compare(result, sim_truth(routine.cell), routine.T_flange_camera_nominal)
    assert out["nominal_error"]["hand_eye_mm"] > 3  # the cell was really off
    assert out["hand_eye_error_mm"] < 1.0 and out["hand_eye_error_deg"] < 0.2
    assert out["axis_error_mm"] < 1.0 and out["axis_error_deg"] < 0.2
    # the reported uncertainty is of the size of the error, not a hundred times off
    assert 0.05 < result.hand_eye_std_mm < 2 and 0.01 < result.axis_std_mm < 1
    assert 0.1 < result.rms_mm < 1.0 and result.residuals_mm.shape == (36,)


def test_a_frame_without_the_target_is_skipped_with_its_reason(routine: Calibration) -> None:
    capture = routine.measure(np.zeros((0, 3)), "empty")
    assert not capture.seen.any()
    far = np.random.default_rng(0).uniform(-1, 1, (5000, 3)) + np.array([0.0, 0.0, 3.0])
    assert not routine.measure(far, "far").seen.any()


def test_an_unreachable_pose_is_skipped_and_too_few_captures_refused() -> None:
    cell = calibration_sim_cell("ideal", "none", seed=1)
    below = CalibrationPose("below-the-plate", 0.0, Pose.look_at([0.0, 0.0, -0.4], DEFAULT_TARGET.centre))
    routine = Calibration(cell, poses=[below])
    with pytest.raises(CalibrationError, match=r"no captures \(1 poses skipped: below-the-plate: unreachable"):
        routine.run()
    assert [label for label, _ in routine.skipped] == ["below-the-plate"] and routine.captures == []
