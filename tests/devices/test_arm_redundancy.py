"""7-DoF IK uses its redundancy: on the Panda and the xArm7 (real kinematics, Pinocchio), the solution is the one
nearest the current joints (not merely the one the seed falls into), it stays continuous along a path of targets,
and it keeps clear of the joint limits."""

from __future__ import annotations

import numpy as np
import pytest

import devices.arm.ik as ik
from devices.arm.config import ArmConfig
from devices.arm.kinematics import ArmKinematics
from planner.types import Pose


@pytest.fixture(scope="module", params=["panda", "xarm7"])
def kinematics(request: pytest.FixtureRequest) -> ArmKinematics:
    return ArmKinematics(ArmConfig(urdf=request.param), 0.15, 0.02)


def _margin(k: ArmKinematics, q: np.ndarray) -> float:
    m = k.model
    return float(np.min(np.minimum(q - m.lower, m.upper - q) / (m.upper - m.lower)))


def test_a_seven_joint_preset_has_seven_joints(kinematics: ArmKinematics) -> None:
    assert kinematics.model.nq == 7 and len(kinematics.home) == 7


def test_the_solution_is_the_nearest_to_the_current_joints(
    kinematics: ArmKinematics, monkeypatch: pytest.MonkeyPatch
) -> None:
    """The same targets and seeds solved with the null-space task and without it: with it, the solutions lie
    several times nearer the current configuration (the seed is perturbed, so the plain iteration lands elsewhere
    on the self-motion manifold)."""
    m = kinematics.model

    def distances() -> list[float]:
        rng = np.random.default_rng(3)
        out = []
        for _ in range(12):
            q_now = np.clip(kinematics.home + rng.normal(0, 0.3, m.nq), m.lower, m.upper)
            target = m.camera_pose(q_now)
            seed = np.clip(q_now + rng.normal(0, 0.4, m.nq), m.lower, m.upper)
            solutions, reason = ik.solve_ik(m, target, [seed], q_now, first=True)
            assert solutions, reason
            pose = m.camera_pose(solutions[0])
            assert np.allclose(pose.translation, target.translation, atol=1e-3)
            out.append(float(np.linalg.norm(solutions[0] - q_now)))
        return out

    with_redundancy = distances()
    monkeypatch.setattr(ik, "NULL_GAIN", 0.0)
    monkeypatch.setattr(ik, "LIMIT_GAIN", 0.0)
    monkeypatch.setattr(ik, "NULL_ITERATIONS", 0)
    plain = distances()
    assert np.mean(with_redundancy) < 0.35 * np.mean(plain)
    assert float(np.median(with_redundancy)) < 0.05


def test_the_solution_is_continuous_along_a_path(kinematics: ArmKinematics) -> None:
    """The camera moved in 4 mm steps: each solution (from the previous one) moves every joint by little, and every
    joint stays clear of its limits."""
    m = kinematics.model
    q = kinematics.home.copy()
    T0 = m.camera_pose(q)
    for i in range(1, 30):
        target = Pose(T0.rotation, T0.translation + np.array([0.004 * i, 0.002 * np.sin(i / 4), -0.002 * i]))
        solutions, reason = ik.solve_ik(m, target, [q], q, first=True)
        assert solutions, reason
        assert float(np.max(np.abs(solutions[0] - q))) < 0.05
        q = solutions[0]
        assert _margin(kinematics, q) > 0.1


def test_the_limit_term_moves_a_solution_off_a_limit(kinematics: ArmKinematics) -> None:
    """A configuration with a joint 1 % of its range from its limit: the IK of its own camera pose, referenced to
    it, moves that joint away from the limit (the redundancy absorbs it) and the camera stays."""
    m = kinematics.model
    rng = np.random.default_rng(5)
    q_edge = kinematics.home.copy()
    j = int(np.argmin(m.upper - m.lower))  # the joint with the narrowest range: its limit matters
    q_edge[j] = m.upper[j] - 0.01 * (m.upper[j] - m.lower[j])
    target = m.camera_pose(q_edge)
    solutions, reason = ik.solve_ik(m, target, [q_edge + rng.normal(0, 1e-3, m.nq)], q_edge, first=True)
    assert solutions, reason
    q = solutions[0]
    assert np.allclose(m.camera_pose(q).translation, target.translation, atol=1e-3)
    assert (m.upper[j] - q[j]) > (m.upper[j] - q_edge[j])
