"""The accumulated cloud with frames taken during moves: a view's points over a move frame's (planner.cloud)."""

from __future__ import annotations

import numpy as np
import pytest

from devices.builtins import make_builtin
from devices.config import CameraConfig, CellConfig
from devices.sim import make_sim_cell
from planner import Planner, PlannerConfig
from planner.cloud import merge_cloud
from planner.preprocess import voxel_downsample
from planner.types import DepthFrame, Pose
from tests.helpers import orbit_view

SIZE = 0.0025


def sheet(z: float, x0: float = 0.0, x1: float = 0.05, step: float = 0.001) -> np.ndarray:
    """(N, 3) points on a square patch at height ``z`` from x0 to x1 (y the same range)."""
    xs = np.arange(x0, x1, step)
    gx, gy = np.meshgrid(xs, np.arange(0.0, 0.05, step))
    return np.stack([gx.ravel(), gy.ravel(), np.full(gx.size, z)], axis=1)


def test_without_move_frames_the_cloud_is_the_down_sampled_union() -> None:
    rng = np.random.default_rng(0)
    a, b = rng.uniform(0, 0.1, (500, 3)), rng.uniform(0, 0.1, (400, 3))
    cloud, flags = merge_cloud(np.zeros((0, 3)), np.zeros(0, dtype=bool), a, False, SIZE, 0.01)
    cloud, flags = merge_cloud(cloud, flags, b, False, SIZE, 0.01)
    np.testing.assert_array_equal(cloud, voxel_downsample(np.concatenate([voxel_downsample(a, SIZE), b]), SIZE))
    assert not flags.any()


def test_a_move_frame_fills_only_what_no_view_measured() -> None:
    view = sheet(0.0)
    cloud, flags = merge_cloud(np.zeros((0, 3)), np.zeros(0, dtype=bool), view, False, SIZE, 0.01)
    n_view = len(cloud)
    late = sheet(0.004)  # the same patch 4 mm off (a late stamp)
    new = sheet(0.0, 0.1, 0.15)  # a patch no view saw, 5 cm beside it
    cloud2, flags2 = merge_cloud(cloud, flags, np.concatenate([late, new]), True, SIZE, 0.01)
    np.testing.assert_array_equal(cloud2[~flags2], cloud)  # the view's points as they were
    assert flags2.sum() == len(voxel_downsample(new, SIZE)) and np.all(cloud2[flags2][:, 0] >= 0.1 - 1e-9)
    # radius 0: the late copy stays where it shares no cell with the view
    cloud0, flags0 = merge_cloud(cloud, flags, late, True, SIZE, 0.0)
    assert flags0.sum() > 0 and len(cloud0) == n_view + flags0.sum()


def test_a_view_replaces_the_move_frames_points_it_measured() -> None:
    empty, none = np.zeros((0, 3)), np.zeros(0, dtype=bool)
    cloud, flags = merge_cloud(empty, none, sheet(0.0, 0.2, 0.25), False, SIZE, 0.01)  # some view elsewhere
    cloud, flags = merge_cloud(cloud, flags, sheet(0.003), True, SIZE, 0.01)  # a move frame, 3 mm off
    assert flags.sum() > 0
    cloud, flags = merge_cloud(cloud, flags, sheet(0.0), False, SIZE, 0.01)  # a view of the same patch
    assert not flags.any()
    assert np.abs(cloud[:, 2]).max() < 1e-9  # only the views' surface is left
    # a cell holding both keeps the view's centroid alone (radius 0: the cell rule only)
    c, f = merge_cloud(empty, none, np.array([[0.0011, 0.0011, 0.0011]]), True, SIZE, 0.0)
    c, f = merge_cloud(c, f, np.array([[0.0001, 0.0001, 0.0001]]), False, SIZE, 0.0)
    np.testing.assert_allclose(c, [[0.0001, 0.0001, 0.0001]])
    assert f.tolist() == [False]


def test_bad_flags_are_refused() -> None:
    with pytest.raises(ValueError, match="from_move"):
        merge_cloud(np.zeros((3, 3)), np.zeros(2, dtype=bool), np.zeros((1, 3)), True, SIZE, 0.01)


def test_a_late_move_frame_leaves_the_views_cloud_as_it_was() -> None:
    """In the planner: a move frame posed 6 mm off (its stamp late) adds nothing where the view measured, and its
    view-side points are gone once a view of its side came; the voxel map takes it all the same."""
    camera = CameraConfig(width=96, height=72, fx=91.0, fy=91.0, cx=47.5, cy=35.5)
    cell = make_sim_cell(make_builtin("l-block", 0.2), camera, CellConfig(kinematics="reach_sphere"), seed=0)
    target = np.array([0.0, 0.0, 0.08])

    def frame(azimuth: float, shift: float = 0.0) -> DepthFrame:
        pose = orbit_view(target, 35, azimuth, 0.45)
        depth = cell.camera.render(pose)  # type: ignore[attr-defined]
        reported = Pose(pose.rotation, pose.translation + np.array([0.0, shift, 0.0]))
        return DepthFrame(depth, reported, camera.intrinsics)

    planner = Planner(PlannerConfig().replace(registration={"enabled": False}))
    planner.integrate(frame(0.0))
    before = planner.cloud.copy()
    planner.integrate(frame(10.0, 0.006), move_frame=True)
    assert planner.cloud_from_move.sum() < 0.1 * len(before)  # the view's side: left out
    np.testing.assert_array_equal(planner.cloud[~planner.cloud_from_move], before)
    planner.integrate(frame(120.0, 0.006), move_frame=True)
    moved = planner.cloud_from_move.sum()
    assert moved > 100  # a side no view saw: kept
    planner.integrate(frame(120.0))
    assert planner.cloud_from_move.sum() < 0.2 * moved  # the view of that side took its place
