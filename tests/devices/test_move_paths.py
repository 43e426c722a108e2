"""The cell's estimate of the camera's path on a move (``Cell.move_paths``, what the ``path`` planner counts): where
each frame will be and how long the move takes, against the path the cell then executes."""

from __future__ import annotations

import math

import numpy as np
import pytest

from devices.arm.config import ArmConfig
from devices.builtins import make_builtin
from devices.cell import Cell
from devices.cellreach import trapezoid_fraction
from devices.config import CameraConfig, CellConfig
from devices.move_capture import camera_path, capture_times
from devices.sim import make_sim_cell
from planner.types import Candidate, Pose
from tests.helpers import orbit_view

TARGET = np.array([0.0, 0.0, 0.08])
SMALL = CameraConfig(width=80, height=60, fx=76.0, fy=76.0, cx=39.5, cy=29.5)
VIEWS = [(10, 20), (10, 300), (30, 90), (45, 200), (20, 160)]
"""(elevation, azimuth) degrees of the views the moves go to, at 0.45 m about ``TARGET``."""


def candidates() -> list[Candidate]:
    return [
        Candidate(i, orbit_view(TARGET, e, a, 0.45), math.radians(e), math.radians(a), 0, 0)
        for i, (e, a) in enumerate(VIEWS)
    ]


def test_trapezoid_fraction() -> None:
    # 1 rad at 1 rad/s and 2 rad/s^2: ramps of 0.5 s (0.25 rad each), 0.5 s of cruise, 1.5 s in all
    assert trapezoid_fraction(-1.0, 1.0, 1.0, 2.0) == 0.0
    assert trapezoid_fraction(0.5, 1.0, 1.0, 2.0) == pytest.approx(0.25)
    assert trapezoid_fraction(0.75, 1.0, 1.0, 2.0) == pytest.approx(0.5)
    assert trapezoid_fraction(1.25, 1.0, 1.0, 2.0) == pytest.approx(1.0 - 0.5 * 2.0 * 0.25**2)
    assert trapezoid_fraction(9.0, 1.0, 1.0, 2.0) == 1.0
    # a short move never reaches the speed: a triangle of 2 sqrt(d / a) = 0.141 s, half way at its middle
    assert trapezoid_fraction(math.sqrt(0.01 / 2.0), 0.01, 1.0, 2.0) == pytest.approx(0.5)
    assert trapezoid_fraction(0.12, 0.01, 1.0, 2.0) == pytest.approx(1.0 - (2.0 * math.sqrt(0.005) - 0.12) ** 2 / 0.01)
    assert trapezoid_fraction(0.3, 0.0, 1.0, 2.0) == 1.0


@pytest.mark.parametrize("overlapped", [False, True])
def test_the_urdf_arms_estimate_is_the_executed_path_when_the_move_is_straight(overlapped: bool) -> None:
    arm = ArmConfig(turn_while_moving=overlapped)
    cell = make_sim_cell(make_builtin("l-block", 0.2), SMALL, CellConfig(arm=arm), seed=0)
    cands = candidates()
    paths = cell.move_paths(cands, range(len(cands)), 5.0)
    compared = 0
    for c, path in zip(cands, paths, strict=True):
        assert path is not None
        motion = cell.plan_motion(c.T_world_camera)
        assert path.seconds == pytest.approx(motion.duration, rel=1e-6)
        times = capture_times(motion.duration, 5.0)
        np.testing.assert_allclose(path.times, times)
        if motion.path_method != "straight" or motion.retract is not None:
            continue  # a path around an obstacle, or a retract: the estimate goes straight (documented)
        executed = camera_path(cell, motion, times)
        gaps = [np.linalg.norm(p.translation - t) for p, t in zip(executed, path.translations, strict=True)]
        assert max(gaps, default=0.0) < 0.01  # ruckig's profile against the trapezoid: well within a voxel
        compared += 1
    assert compared >= 3
    assert any(len(p) >= 5 for p in paths if p is not None)  # moves long enough to sweep (> 1 s at 5 Hz)


def test_the_reach_spheres_paths_are_exact_and_an_unreachable_view_has_none() -> None:
    cell: Cell = make_sim_cell(make_builtin("l-block", 0.2), SMALL, CellConfig(kinematics="reach_sphere"), seed=0)
    cands = candidates()
    below = Candidate(len(cands), Pose.look_at(np.array([0.3, 0.0, -0.2]), TARGET), -0.5, 0.0, 0, 0)
    paths = cell.move_paths([*cands, below], range(len(cands) + 1), 2.5)
    assert paths[-1] is None
    for c, path in zip(cands, paths[:-1], strict=True):
        assert path is not None
        motion = cell.plan_motion(c.T_world_camera)
        executed = camera_path(cell, motion, path.times)
        np.testing.assert_allclose(np.stack([p.translation for p in executed]), path.translations, atol=1e-9)
    with pytest.raises(ValueError, match="capture_hz"):
        cell.move_paths(cands, [0], -1.0)
