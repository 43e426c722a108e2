"""Calibration and motion error: the camera renders from the true pose, the cell reports the nominal one."""

from __future__ import annotations

import math

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from devices.builtins import make_builtin
from devices.calibration_error import CALIBRATIONS, CellErrors, calibration_named
from devices.config import CameraConfig, CellConfig
from devices.sim import make_sim_cell
from planner.types import Pose


def offset(a: Pose, b: Pose) -> tuple[float, float]:
    """(metres, degrees) between two poses."""
    d = a.inverse() @ b
    return float(np.linalg.norm(a.translation - b.translation)), math.degrees(
        Rotation.from_matrix(d.rotation).magnitude()
    )


def test_none_renders_from_the_reported_pose() -> None:
    cell = make_sim_cell(make_builtin("l-block"), CameraConfig(), CellConfig(), seed=1)
    assert cell.camera.pose_source is not None
    assert offset(cell.camera.pose_source(), cell.pose) == (0.0, 0.0)


@pytest.mark.parametrize(("name", "max_mm"), [("typical", 6.0), ("poor", 25.0)])
def test_true_pose_departs_from_the_nominal_by_the_model(name: str, max_mm: float) -> None:
    cell = make_sim_cell(make_builtin("l-block"), CameraConfig(calibration=name), CellConfig(), seed=1)
    assert cell.camera.pose_source is not None
    true = cell.camera.pose_source()
    metres, _ = offset(true, cell.pose)
    assert 0.0 < metres * 1000 < max_mm
    frame = cell.capture()
    assert offset(frame.T_world_camera, cell.pose) == (0.0, 0.0)  # the frame carries the nominal pose
    assert offset(cell.camera.pose_source(), true) == (0.0, 0.0)  # the same configuration: the same error


def test_the_bias_is_fixed_by_the_seed_and_exposed() -> None:
    model = calibration_named("typical")
    a, b, c = CellErrors(model, 5), CellErrors(model, 5), CellErrors(model, 6)
    assert np.array_equal(a.E_hand_eye.matrix, b.E_hand_eye.matrix)
    assert not np.array_equal(a.E_hand_eye.matrix, c.E_hand_eye.matrix)
    nominal = Pose(np.eye(3), np.array([0.0, 0.05, 0.04]))
    true = a.T_flange_camera_true(nominal)
    metres, degrees = offset(nominal, true)
    assert 0 < metres < 0.006 and 0 < degrees < 1.5
    assert a.summary()["calibration"] == "typical"


def test_per_move_noise_depends_on_the_configuration() -> None:
    errors = CellErrors(calibration_named("poor"), 2)
    nominal = Pose(np.eye(3), np.array([0.3, 0.0, 0.3]))
    one = errors.true_T_table_camera(nominal, 0.5, b"q1")
    again = errors.true_T_table_camera(nominal, 0.5, b"q1")
    other = errors.true_T_table_camera(nominal, 0.5, b"q2")
    assert offset(one, again) == (0.0, 0.0)
    assert 0 < offset(one, other)[0] < 0.005


def test_turntable_axis_error_turns_about_the_true_axis() -> None:
    errors = CellErrors(calibration_named("poor"), 3)
    axis = errors.T_base_axis
    assert np.linalg.norm(axis.translation[:2]) > 0
    on_axis = axis.translation
    moved = errors.T_base_table_true(1.0).apply(on_axis[None, :])[0]
    assert np.allclose(moved[:2], on_axis[:2], atol=errors.model.axis_offset * 0.01 + 1e-4)


def test_names() -> None:
    assert list(CALIBRATIONS) == ["none", "typical", "poor"]
    with pytest.raises(ValueError, match="known: none, typical, poor"):
        calibration_named("great")
