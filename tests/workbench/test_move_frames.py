"""Frames taken during moves: which are kept (new coverage, the integration-time budget), what they do to the map,
and how the bench counts them in the robot time to coverage."""

from __future__ import annotations

import itertools

import numpy as np
import pytest

from devices.builtins import make_builtin
from devices.config import CameraConfig, CellConfig
from devices.move_capture import MoveFrame
from devices.sim import make_sim_cell
from planner import Planner, PlannerConfig
from planner.types import DepthFrame, Pose
from tests.helpers import orbit_view
from workbench.evaluation.curves import run_metrics, time_to_reach
from workbench.move_frames import KeepRule, integrate_move_frames, new_share

SMALL = CameraConfig(width=96, height=72, fx=91.0, fy=91.0, cx=47.5, cy=35.5)
TARGET = np.array([0.0, 0.0, 0.08])


@pytest.fixture(scope="module")
def scene():
    cell = make_sim_cell(make_builtin("l-block", 0.2), SMALL, CellConfig(kinematics="reach_sphere"), seed=0)

    def frame(azimuth: float) -> DepthFrame:
        pose = orbit_view(TARGET, 35, azimuth, 0.45)
        return DepthFrame(cell.camera.render(pose), pose, SMALL.intrinsics)  # type: ignore[attr-defined]

    return frame


def test_time_to_reach_counts_a_move_frame_at_its_time() -> None:
    ratios, seconds = [0.5, 0.96], [2.0, 5.0]
    moves = [[], [(1.0, 0.8), (2.5, 0.95)]]
    assert time_to_reach(ratios, seconds, 0.95) == pytest.approx(7.0)
    assert time_to_reach(ratios, seconds, 0.95, moves) == pytest.approx(2.0 + 2.5)
    assert time_to_reach(ratios, seconds, 0.80, moves) == pytest.approx(2.0 + 1.0)
    assert time_to_reach(ratios, seconds, 0.99, moves) == pytest.approx(7.0 * 1.5)  # never: the penalty
    with pytest.raises(ValueError, match="moves"):
        time_to_reach(ratios, seconds, 0.9, [[]])
    metrics = run_metrics([0.45, 0.9], 0.9375, 2, seconds, [[], [(1.0, 0.75), (2.5, 0.9)]])
    assert metrics.time_to == pytest.approx((4.5, 4.5))  # 0.9 / 0.9375 = 0.96 of the ceiling at 2.5 s in


def test_a_frame_of_what_the_map_holds_is_left_out_and_a_new_side_is_kept(scene) -> None:
    planner = Planner(PlannerConfig())
    view = scene(0.0)
    planner.integrate(view)
    assert new_share(planner, view) < 0.02
    assert new_share(planner, scene(180.0)) > 0.3 and new_share(planner, scene(2.0)) < 0.02
    points = len(planner.cloud)
    frames = [MoveFrame(scene(5.0), 0.4), MoveFrame(scene(180.0), 0.8)]
    out = integrate_move_frames(planner, frames, 2.0, KeepRule(min_new=0.05, wait=0.1))
    assert (out.taken, len(out.kept), out.seen, out.late, out.rejected) == (2, 1, 1, 0, 0)
    assert out.kept[0].t == 0.8 and out.kept[0].new_share > 0.3
    assert len(planner.cloud) > points
    assert planner.iteration == 1 and len(planner.point_counts) == 1  # a move frame is no view
    assert out.to_json()["kept"] == 1


def test_frames_taken_faster_than_the_limit_are_left_out(scene) -> None:
    planner = Planner(PlannerConfig())
    planner.integrate(scene(0.0))
    frames = [MoveFrame(scene(90.0), 0.2, 1.2), MoveFrame(scene(180.0), 0.4, 0.3), MoveFrame(scene(270.0), 0.6)]
    out = integrate_move_frames(planner, frames, 5.0, KeepRule(min_new=0.0, wait=1.0, max_speed=0.5))
    assert ([k.t for k in out.kept], out.fast) == ([0.4, 0.6], 1)  # a frame without a speed is not judged by it
    assert out.to_json()["fast"] == 1


def test_frames_that_would_make_the_move_wait_are_left_out(scene) -> None:
    planner = Planner(PlannerConfig())
    planner.integrate(scene(0.0))
    ticks = itertools.count(0.0, 0.3)  # every clock read 0.3 s later: each frame costs 0.3 s
    frames = [MoveFrame(scene(a), t) for a, t in ((90.0, 0.1), (180.0, 0.2), (270.0, 0.3), (300.0, 0.9))]
    out = integrate_move_frames(planner, frames, 1.0, KeepRule(min_new=0.0, wait=0.1), clock=lambda: next(ticks))
    # frame 1 runs 0.1-0.4, frame 2 0.4-0.7, frame 3 0.7-1.0; frame 4 would start at 1.0 and end at 1.3 > 1.1
    assert len(out.kept) == 3 and out.late == 1
    assert out.integration_seconds == pytest.approx(0.9)
    assert out.wait_seconds == pytest.approx(0.0)
    unbounded = Planner(PlannerConfig())
    unbounded.integrate(scene(0.0))
    ticks = itertools.count(0.0, 0.3)
    out = integrate_move_frames(unbounded, frames, 1.0, KeepRule(min_new=0.0, wait=10.0), clock=lambda: next(ticks))
    assert len(out.kept) == 4 and out.wait_seconds == pytest.approx(0.3)  # 1.3 s: the move waits 0.3 s


def test_a_frame_icp_cannot_confirm_is_refused_when_the_rule_asks_for_registration(scene) -> None:
    planner = Planner(PlannerConfig())
    planner.integrate(scene(0.0))
    good = scene(20.0)
    off = good.with_pose(
        Pose(good.T_world_camera.rotation, good.T_world_camera.translation + np.array([0.0, 0.0, 0.06]))
    )
    points = len(planner.cloud)
    with pytest.raises(ValueError, match="registration"):
        planner.integrate(off, move_frame=True, registered=True)
    assert len(planner.cloud) == points  # nothing changed
    out = integrate_move_frames(planner, [MoveFrame(off, 0.2), MoveFrame(good, 0.4)], 1.0, KeepRule(0.0, 1.0, True))
    assert (len(out.kept), out.rejected) == (1, 1) and out.kept[0].t == 0.4
