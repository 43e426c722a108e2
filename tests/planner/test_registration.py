"""register: point-to-plane ICP recovers known perturbations; the gate rejects bad results with reasons."""

from __future__ import annotations

import subprocess
import sys

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from planner.config import RegistrationConfig
from planner.registration import RegistrationResult, register
from planner.types import Pose

LOWER, UPPER = np.array([-0.05, -0.035, 0.0]), np.array([0.05, 0.035, 0.05])  # an asymmetric box


def _box_faces(n: int, seed: int) -> np.ndarray:
    """(n, 3) points uniform on the box's +x, +y and +z faces (what a camera at a corner sees)."""
    rng = np.random.default_rng(seed)
    ext = UPPER - LOWER
    areas = np.array([ext[1] * ext[2], ext[0] * ext[2], ext[0] * ext[1]])
    face = rng.choice(3, size=n, p=areas / areas.sum())
    p = LOWER + rng.random((n, 3)) * ext
    p[np.arange(n), face] = UPPER[face]
    return p


def _perturbation() -> Pose:
    """1 degree about a tilted axis through (0.2, -0.1, 0.3), plus a 5 mm translation."""
    R = Rotation.from_rotvec(
        np.radians(1.0) * np.array([0.3, -0.5, 0.8]) / np.linalg.norm([0.3, -0.5, 0.8])
    ).as_matrix()
    pivot = np.array([0.2, -0.1, 0.3])
    return Pose(R, pivot - R @ pivot + np.array([0.003, -0.004, 0.0]))


def test_known_perturbation_of_a_partial_view_is_recovered() -> None:
    target = _box_faces(12000, seed=1)
    view = _box_faces(8000, seed=2)
    view = view[view[:, 0] > -0.02]  # a partial view of the same faces
    wrong = _perturbation()
    result = register(wrong.apply(view), target, RegistrationConfig())
    assert isinstance(result, RegistrationResult)
    assert result.accepted, result.reason
    assert result.reason.startswith("ok: fitness")
    assert result.unconstrained == 0
    recovered = (result.correction @ wrong).apply(view)
    assert np.max(np.linalg.norm(recovered - view, axis=1)) < 0.001
    assert result.fitness > 0.95 and result.rmse < 0.001
    shift = np.linalg.norm(
        wrong.inverse().apply(wrong.apply(view).mean(axis=0)[None])[0] - wrong.apply(view).mean(axis=0)
    )
    assert result.shift == pytest.approx(shift, abs=0.001)


def test_unconstrained_directions_are_left_alone() -> None:
    # A spherical cap only fixes the translation: rotations about the centre are free.
    rng = np.random.default_rng(0)
    d = rng.normal(size=(40000, 3))
    d /= np.linalg.norm(d, axis=1, keepdims=True)
    centre = np.array([0.0, 0.0, 0.05])
    target = centre + 0.05 * d[:20000][d[:20000, 0] > -0.2]
    view = centre + 0.05 * d[20000:][d[20000:, 0] > 0.1]
    offset = np.array([0.003, -0.002, 0.004])
    result = register(view + offset, target, RegistrationConfig())
    assert result.accepted, result.reason
    assert result.unconstrained == 3
    assert "3 unconstrained direction(s) left uncorrected" in result.reason
    np.testing.assert_allclose(result.correction.apply((view + offset)[:100]), view[:100], atol=0.001)
    angle = np.degrees(np.arccos(np.clip((np.trace(result.correction.rotation) - 1) / 2, -1, 1)))
    assert angle < 0.2


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_garbage_target_is_rejected_with_numbers(seed: int) -> None:
    view = _box_faces(5000, seed=2)
    garbage = np.random.default_rng(seed).random((5000, 3)) - 0.5  # a sparse cloud in a 1 m cube
    result = register(view, garbage, RegistrationConfig())
    assert not result.accepted
    assert result.reason.startswith("rejected: fitness 0.0")
    assert "< min_fitness 0.300" in result.reason
    np.testing.assert_array_equal(result.correction.matrix, np.eye(4))


def test_another_object_is_rejected() -> None:
    view = _box_faces(5000, seed=2)
    d = np.random.default_rng(0).normal(size=(20000, 3))
    sphere = np.array([0.03, 0.0, 0.025]) + 0.05 * d / np.linalg.norm(d, axis=1, keepdims=True)
    assert not register(view, sphere, RegistrationConfig()).accepted
    # The same box turned 90 degrees about z: ICP half-fits it, the point-to-plane rmse gives it away.
    turned = view @ np.array([[0.0, -1.0, 0.0], [1.0, 0.0, 0.0], [0.0, 0.0, 1.0]]).T
    result = register(view, turned, RegistrationConfig(max_rmse=0.0025))
    assert not result.accepted
    assert "mm > max_rmse 2.50 mm" in result.reason
    assert result.rmse > 0.0025


def test_a_large_correction_is_rejected() -> None:
    target = _box_faces(12000, seed=1)
    view = _box_faces(8000, seed=2)
    wrong = _perturbation()
    result = register(wrong.apply(view), target, RegistrationConfig(max_correction=0.002))
    assert not result.accepted
    assert "mm > max_correction 2.0 mm" in result.reason
    assert "fitness" not in result.reason  # only the failed gate is listed
    assert result.shift > 0.004
    np.testing.assert_array_equal(result.correction.matrix, np.eye(4))


def test_tight_gates_list_every_failure() -> None:
    view = np.concatenate(
        [_box_faces(3000, seed=2), _box_faces(300, seed=3) + np.array([0.0, 0.0, 0.2])]
    )  # 9 % far away
    result = register(view, _box_faces(3000, seed=1), RegistrationConfig(min_fitness=0.99, max_rmse=1e-6))
    assert not result.accepted
    assert "< min_fitness 0.990" in result.reason and "> max_rmse 0.00 mm" in result.reason


@pytest.mark.parametrize(
    ("source", "target", "reason"),
    [
        (np.zeros((0, 3)), np.ones((10, 3)), "source has 0 points (need >= 3)"),
        (np.ones((10, 3)), np.zeros((2, 3)), "target has 2 points (need >= 3)"),
    ],
)
def test_empty_clouds_are_not_accepted(source: np.ndarray, target: np.ndarray, reason: str) -> None:
    result = register(source, target, RegistrationConfig())
    assert not result.accepted and result.reason == reason
    np.testing.assert_array_equal(result.correction.matrix, np.eye(4))


def test_disabled_and_bad_input() -> None:
    result = register(_box_faces(100, 0), _box_faces(100, 1), RegistrationConfig(enabled=False))
    assert not result.accepted and result.reason == "registration disabled"
    with pytest.raises(ValueError, match="source_world: 1 non-finite"):
        register(np.array([[np.nan, 0.0, 0.0]]), _box_faces(100, 1), RegistrationConfig())
    with pytest.raises(ValueError, match=r"target_world: expected shape \(N, 3\)"):
        register(_box_faces(100, 1), np.zeros((5, 2)), RegistrationConfig())


def test_planner_modules_do_not_import_open3d() -> None:
    code = "import sys, planner.preprocess, planner.registration; print('open3d' in sys.modules)"
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    assert out.stdout.strip() == "False"
