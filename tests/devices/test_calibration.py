"""Calibration maths on synthetic data: sphere fits, hand-eye and axis from exact poses, bad input, the cell file."""

from __future__ import annotations

import math
import textwrap
from pathlib import Path

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from devices.calibration import (
    DEFAULT_TARGET,
    CalibrationError,
    Capture,
    ErrorBudget,
    SphereFit,
    axis_error,
    calibrated_cell_text,
    estimate,
    find_spheres,
    fit_sphere,
    pose_error,
    write_calibration,
)
from devices.calibration.result import CalibrationResult
from devices.cellfile import load_cell_file
from planner.types import Pose


def _rz(theta: float) -> Pose:
    return Pose(Rotation.from_euler("z", theta).as_matrix(), np.zeros(3))


def test_sphere_fit_on_a_noisy_cap_recovers_centre_and_radius() -> None:
    rng = np.random.default_rng(3)
    centre, radius = np.array([0.02, -0.01, 0.45]), 0.02
    # the cap a camera at the origin sees: directions within 70 degrees of the one towards the camera
    towards = -centre / np.linalg.norm(centre)
    d = rng.normal(size=(20000, 3))
    d /= np.linalg.norm(d, axis=1, keepdims=True)
    d = d[d @ towards > math.cos(math.radians(70))][:3000]
    points = centre + radius * d + rng.normal(0.0, 0.0005, (len(d), 3))
    free = fit_sphere(points)
    assert np.linalg.norm(free.centre - centre) < 2e-4
    assert abs(free.radius - radius) < 2e-4
    known = fit_sphere(points, radius=radius)
    assert np.linalg.norm(known.centre - centre) < 1e-4 and known.radius == radius
    assert 0.0003 < known.rms < 0.0007  # the noise, not the bias of a wrong model
    with pytest.raises(ValueError, match="at least 60 points"):
        fit_sphere(points[:10])


def test_the_sphere_fit_agrees_with_a_fit_by_numerical_derivatives() -> None:
    """fit_sphere gives least_squares its residuals' analytic Jacobian; the same robust fit with scipy's finite
    differences (its default, before) lands on the same sphere."""
    from scipy.optimize import least_squares

    from devices.calibration.spheres import LOSS_SCALE, TRIM

    rng = np.random.default_rng(5)
    centre, radius = np.array([-0.03, 0.02, 0.5]), 0.025
    d = rng.normal(size=(4000, 3))
    d /= np.linalg.norm(d, axis=1, keepdims=True)
    d = d[d @ (-centre / np.linalg.norm(centre)) > 0.4]
    points = centre + radius * d + rng.normal(0.0, 0.001, (len(d), 3))
    start = points.mean(axis=0)
    fit = fit_sphere(points, start=start)  # one pass over every point, then the points near that fit
    x = np.append(start, np.linalg.norm(points - start, axis=1).mean())
    for trim in (None, TRIM):
        q = points if trim is None else points[np.abs(np.linalg.norm(points - x[:3], axis=1) - x[3]) < trim]

        def residual(v: np.ndarray, q: np.ndarray = q) -> np.ndarray:
            return np.linalg.norm(q - v[:3], axis=1) - v[3]

        x = least_squares(residual, x, loss="soft_l1", f_scale=LOSS_SCALE, method="trf").x
    assert np.linalg.norm(fit.centre - x[:3]) < 1e-7 and abs(fit.radius - x[3]) < 1e-7
    assert np.linalg.norm(fit.centre - centre) < 5e-4  # and it is the sphere


def _synthetic(
    X: Pose, A: Pose, flange_rotvecs: list[np.ndarray], angles_deg: list[float], P: np.ndarray
) -> list[Capture]:
    """Exact captures: the camera at the arm's side looking at the target, rotated per capture."""
    captures = []
    for i, (rotvec, angle_deg) in enumerate(zip(flange_rotvecs, angles_deg, strict=True)):
        eye = np.array([-0.35, 0.0, 0.45])
        T_base_camera = Pose.look_at(eye, [0.0, 0.0, 0.12])
        T_base_camera = Pose(T_base_camera.rotation @ Rotation.from_rotvec(rotvec).as_matrix(), eye)
        T_base_flange = T_base_camera @ X.inverse()
        theta = math.radians(angle_deg)
        T_base_table = A @ _rz(theta) @ A.inverse()
        centres = (T_base_camera.inverse() @ T_base_table).apply(P)
        captures.append(Capture(T_base_flange, theta, centres, np.zeros(len(P)), f"c{i}"))
    return captures


X_TRUE = Pose(Rotation.from_euler("xyz", [1.0, -0.7, 91.0], degrees=True).as_matrix(), np.array([0.003, 0.052, 0.041]))
A_TRUE = Pose(Rotation.from_rotvec([0.004, -0.003, 0.0]).as_matrix(), np.array([0.0015, -0.002, 0.0]))


def _varied(n: int) -> tuple[list[np.ndarray], list[float]]:
    rng = np.random.default_rng(1)
    rotvecs = [rng.normal(0.0, 0.35, 3) for _ in range(n)]
    angles = [float(a) for a in np.resize([0.0, 60.0, 120.0, 180.0, -120.0, -60.0], n)]
    return rotvecs, angles


def test_hand_eye_and_axis_from_exact_poses_to_a_micrometre() -> None:
    rotvecs, angles = _varied(12)
    # the nominal X the cell would hold is irrelevant: OpenCV starts from the data
    result = estimate(_synthetic(X_TRUE, A_TRUE, rotvecs, angles, DEFAULT_TARGET.centres_table), DEFAULT_TARGET)
    mm, deg = pose_error(result.T_flange_camera, X_TRUE)
    assert mm < 1e-3 and deg < 1e-4  # 1e-6 m, ~2e-6 rad
    axis_mm, axis_deg = axis_error(
        result.axis_point_base, result.axis_direction_base, A_TRUE.translation, A_TRUE.rotation[:, 2]
    )
    assert axis_mm < 1e-3 and axis_deg < 1e-4
    assert np.abs(result.centres_table - DEFAULT_TARGET.centres_table).max() < 1e-6
    assert result.rms_mm < 1e-3 and result.residuals_mm.shape == (12,)
    # exact data: no spread of its own; what is left is the error budget (a centre bias moves the hand-eye
    # translation one to one: at least its 0.2 mm per axis, about 0.35 mm as a norm of three)
    assert 0.3 < result.hand_eye_std_mm < 1.0 and result.hand_eye_bound95_mm > result.hand_eye_std_mm
    bare = estimate(
        _synthetic(X_TRUE, A_TRUE, rotvecs, angles, DEFAULT_TARGET.centres_table),
        DEFAULT_TARGET,
        budget=ErrorBudget(0.0, 0.0, 0.0),
    )
    assert bare.hand_eye_std_mm < 1e-3 and bare.axis_std_mm < 1e-3


def test_the_error_budget_adds_the_arm_repeatability_and_the_centre_bias() -> None:
    rotvecs, angles = _varied(12)
    captures = _synthetic(X_TRUE, A_TRUE, rotvecs, angles, DEFAULT_TARGET.centres_table)
    bias = estimate(captures, DEFAULT_TARGET, budget=ErrorBudget(0.0, 0.0, 0.001))
    # a bias common to every centre is a hand-eye translation: 1 mm per axis, sqrt(3) mm as a norm
    assert bias.hand_eye_std_mm == pytest.approx(math.sqrt(3), rel=0.02)
    arm = estimate(captures, DEFAULT_TARGET, budget=ErrorBudget(0.001, 0.0, 0.0))
    # a random displacement per capture averages down somewhat over the 12 captures, and reaches the axis too
    assert 0.1 < arm.hand_eye_std_mm < bias.hand_eye_std_mm and arm.axis_std_mm > 0.05
    # the 95 % bound of a 2D error's norm: 1.73 sigma-norms (isotropic) to 1.96 (all along one axis)
    assert 1.7 < arm.axis_bound95_mm / arm.axis_std_mm < 2.0


def test_too_few_captures_is_a_clear_error() -> None:
    rotvecs, angles = _varied(4)
    with pytest.raises(CalibrationError, match="4 captures saw three or more spheres, need at least 6"):
        estimate(_synthetic(X_TRUE, A_TRUE, rotvecs, angles, DEFAULT_TARGET.centres_table), DEFAULT_TARGET)
    with pytest.raises(CalibrationError, match="no captures"):
        estimate([], DEFAULT_TARGET)


def test_one_plate_angle_is_a_clear_error() -> None:
    rotvecs, _ = _varied(8)
    captures = _synthetic(X_TRUE, A_TRUE, rotvecs, [30.0] * 8, DEFAULT_TARGET.centres_table)
    with pytest.raises(CalibrationError, match="1 plate angles, need at least 3"):
        estimate(captures, DEFAULT_TARGET)


def test_poses_all_about_one_axis_are_degenerate() -> None:
    # one camera pose looking straight down, only the plate turning: in the plate frame every rotation between
    # captures is about the vertical (the hand-eye offset along it cannot be found)
    angles = [0.0, 45.0, 90.0, 135.0, 180.0, -135.0, -90.0, -45.0]
    captures = []
    for i, angle_deg in enumerate(angles):
        down = Pose.look_at([0.0, 0.0, 0.6], [0.0, 0.0, 0.0], up=(1.0, 0.0, 0.0))
        T_base_flange = down @ X_TRUE.inverse()
        theta = math.radians(angle_deg)
        centres = (down.inverse() @ _rz(theta)).apply(DEFAULT_TARGET.centres_table)
        captures.append(Capture(T_base_flange, theta, centres, np.zeros(4), f"c{i}"))
    with pytest.raises(CalibrationError, match="degenerate poses: the camera turns about one axis only"):
        estimate(captures, DEFAULT_TARGET)


def test_target_not_seen_is_a_clear_error() -> None:
    rotvecs, angles = _varied(8)
    captures = _synthetic(X_TRUE, A_TRUE, rotvecs, angles, DEFAULT_TARGET.centres_table)
    blind = [Capture(c.T_base_flange, c.plate_angle, np.full((4, 3), np.nan), np.full(4, np.nan)) for c in captures]
    with pytest.raises(CalibrationError, match="the target was not seen in any of the 8 captures"):
        estimate(blind, DEFAULT_TARGET)


CELL = """\
# the lab's cell
[devices]
allow_auto = false

[devices.camera]
driver = "sim"

[devices.hand_eye]            # measured by hand
translation = [0.0, 0.0, 0.05]
rotation_deg = [0.0, 0.0, 0.0]

[devices.arm_base]
translation = [-0.85, 0.0, 0.0]
rotation_deg = [0.0, 0.0, 0.0]

[planner]
resolution = 0.01
"""


def _result() -> CalibrationResult:
    return CalibrationResult(
        T_flange_camera=X_TRUE,
        axis_point_base=A_TRUE.translation,
        axis_direction_base=A_TRUE.rotation[:, 2],
        centres_table=DEFAULT_TARGET.centres_table,
        hand_eye_std_mm=0.3,
        hand_eye_std_deg=0.05,
        axis_std_mm=0.1,
        axis_std_deg=0.04,
        residuals_mm=np.array([0.2, 0.3]),
        rms_mm=0.25,
        labels=("a", "b"),
        T_flange_camera_initial=X_TRUE,
    )


def test_writing_the_cell_file_keeps_a_backup_and_round_trips(tmp_path: Path) -> None:
    path = tmp_path / "cell.toml"
    path.write_text(CELL)
    backup = write_calibration(path, _result())
    assert backup.read_text() == CELL and backup.name.startswith("cell.toml.") and backup.suffix == ".bak"
    cell = load_cell_file(path)
    assert np.allclose(cell.hand_eye.matrix, X_TRUE.matrix, atol=1e-6)
    # the base frame moves onto the measured axis: the arm base by minus its offset
    assert np.allclose(cell.arm_base.translation, [-0.85 - 0.0015, 0.002, 0.0], atol=1e-9)
    text = path.read_text()
    assert "# the lab's cell" in text and "[planner]\nresolution = 0.01" in text  # the rest is kept
    assert "tilt 0.286 deg" in text  # the tilt, reported, and written as data
    assert np.allclose(cell.turntable_axis, _result().axis_direction_base, atol=1e-7)
    sections = ("[devices.hand_eye]", "[devices.arm_base]", "[devices.turntable_axis]")
    assert all(text.count(name) == 1 for name in sections)
    # writing again round-trips: the same values, a second backup
    again = write_calibration(path, _result())
    assert again.exists() and np.allclose(load_cell_file(path).hand_eye.matrix, X_TRUE.matrix, atol=1e-6)


def test_a_cell_file_without_the_sections_gets_them(tmp_path: Path) -> None:
    text = calibrated_cell_text('[devices]\n[devices.camera]\ndriver = "sim"\n', _result(), Pose.identity())
    path = tmp_path / "c.toml"
    path.write_text(text)
    cell = load_cell_file(path)
    assert np.allclose(cell.hand_eye.matrix, X_TRUE.matrix, atol=1e-6)
    assert np.allclose(cell.arm_base.translation, [-0.0015, 0.002, 0.0])


def test_a_bad_cell_file_is_refused_and_left_alone(tmp_path: Path) -> None:
    path = tmp_path / "cell.toml"
    bad = textwrap.dedent("""\
        [devices]
        hand_eye = { translation = [0, 0, 0.05] }
        """)
    path.write_text(bad)
    with pytest.raises(ValueError):
        write_calibration(path, _result())
    assert path.read_text() == bad and sorted(p.name for p in tmp_path.iterdir()) == ["cell.toml"]


def _cap(centre: np.ndarray, radius: float, rng: np.random.Generator, n: int = 3000) -> np.ndarray:
    """(~n, 3) noisy points of the cap of a sphere that a camera at the origin sees."""
    d = rng.normal(size=(4 * n, 3))
    d /= np.linalg.norm(d, axis=1, keepdims=True)
    d = d[d @ (-centre / np.linalg.norm(centre)) > 0.3][:n]
    return centre + radius * d + rng.normal(0.0, 0.0004, (len(d), 3))


def _find_spheres_over_every_point(
    p: np.ndarray, pred: np.ndarray, radius: float, window: float = 0.03
) -> list[SphereFit | None]:
    """find_spheres as it was written first: the distances of every point to every prediction."""
    from devices.calibration.spheres import MIN_POINTS, TRIM

    distances = np.linalg.norm(p[:, None, :] - pred[None, :, :], axis=2)
    nearest = distances.argmin(axis=1)
    out: list[SphereFit | None] = []
    for k in range(len(pred)):
        mask = (nearest == k) & (distances[:, k] < radius + window)
        if int(mask.sum()) < MIN_POINTS:
            out.append(None)
            continue
        try:
            fit = fit_sphere(p[mask], radius, start=pred[k])
            fit = fit_sphere(p[np.linalg.norm(p - fit.centre, axis=1) < radius + TRIM], radius, start=fit.centre)
        except ValueError:
            out.append(None)
            continue
        out.append(fit if float(np.linalg.norm(fit.centre - pred[k])) < window else None)
    return out


def test_find_spheres_searches_near_the_predictions_and_finds_what_every_point_would() -> None:
    """find_spheres looks only at the points in the boxes of the predictions' windows (and at every point when a
    fit lands near a window's edge): the same fits, to the bit, as distances over every point of the frame."""
    rng = np.random.default_rng(11)
    radius = 0.02
    truth = np.array([[0.05, 0.0, 0.5], [-0.06, 0.02, 0.52], [0.0, -0.07, 0.48], [0.12, 0.1, 0.6]])
    shift = np.array([[0.002, -0.001, 0.001], [0.0, 0.0, 0.0], [0.0285, 0.0, 0.0], [0.0, 0.0, 0.0]])
    # sphere 3's prediction lies 2.85 cm from it along x: its fit lands near the window's edge, and the points of a
    # post 2.25 cm from its centre on the far side (within the second fit's reach) lie outside the prediction's box
    # (the search over all points); sphere 4 is not in the frame (None); a plate behind and a post below sphere 1
    plate = np.column_stack([rng.uniform(-0.3, 0.3, 60000), rng.uniform(-0.2, 0.2, 60000), np.full(60000, 0.7)])
    post = np.column_stack(
        [rng.uniform(0.045, 0.055, 2000), rng.uniform(0.02, 0.2, 2000), rng.uniform(0.49, 0.5, 2000)]
    )
    far = truth[2] + np.column_stack([np.full(300, -0.0225), rng.uniform(-0.002, 0.002, (300, 2))])
    p = np.vstack([plate, post, far, *(_cap(c, radius, rng) for c in truth[:3])])
    p = p[rng.permutation(len(p))]
    pred = truth + shift
    got = find_spheres(p, pred, radius)
    want = _find_spheres_over_every_point(p, pred, radius)
    assert [g is None for g in got] == [w is None for w in want] == [False, False, False, True]
    for g, w, c in zip(got[:3], want[:3], truth[:3], strict=True):
        assert g is not None and w is not None
        assert np.array_equal(g.centre, w.centre) and g.rms == w.rms and g.points == w.points
        assert np.linalg.norm(g.centre - c) < 5e-4
    assert find_spheres(np.zeros((0, 3)), pred, radius) == [None] * 4
