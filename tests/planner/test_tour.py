"""The ``tour`` planner: visibility on a z-buffer, a set cover that counts a voxel once, the tour's order under
known move times, and a plan with the simulated cell."""

from __future__ import annotations

import math

import numpy as np
import pytest

from planner import Planner, PlannerConfig
from planner.config import TourConfig
from planner.evaluators import evaluator_names
from planner.tour import greedy_cover, path_seconds, rate_order, tour_order, visible_frontier
from planner.types import Intrinsics, Pose

K = Intrinsics(width=64, height=48, fx=60.0, fy=60.0, cx=31.5, cy=23.5)


def line_times(positions: list[float], speed: float = 1.0) -> np.ndarray:
    """(K + 1, K + 1) seconds between views on a line (state 0 at the first position)."""
    x = np.array(positions)
    return np.abs(x[:, None] - x[None, :]) / speed


def test_tour_order_on_a_line_visits_the_views_in_their_order_along_it() -> None:
    # the robot at 0; views (states 1..5) at 4, 1, 5, 2, 3: the shortest open path goes 1, 2, 3, 4, 5 along the line
    times = line_times([0.0, 4.0, 1.0, 5.0, 2.0, 3.0])
    order, method = tour_order(times)
    assert method == "lkh"
    assert order == [2, 4, 5, 1, 3]
    assert path_seconds(times, order) == pytest.approx(5.0)


def test_tour_order_from_the_middle_goes_to_the_nearer_end_first() -> None:
    # robot at 0, views at -1, 3, -2, 1: the nearer end (-2) first costs 2 + 5 = 7, the far end first 3 + 5 = 8
    times = line_times([0.0, -1.0, 3.0, -2.0, 1.0])
    order, _ = tour_order(times)
    assert order == [1, 3, 4, 2]
    assert path_seconds(times, order) == pytest.approx(7.0)


def test_tour_order_with_a_given_first_view_and_the_small_cases() -> None:
    times = line_times([0.0, 4.0, 1.0, 5.0, 2.0, 3.0])
    order, _ = tour_order(times, start_with=3)  # the view at 5 first, then back down the line
    assert order == [3, 1, 5, 4, 2]
    assert tour_order(line_times([0.0, 2.0, 1.0]))[0] == [2, 1]
    assert tour_order(line_times([0.0, 2.0])) == ([1], "exact")
    assert tour_order(np.zeros((1, 1))) == ([], "exact")
    with pytest.raises(ValueError, match=r"^times: need a finite"):
        tour_order(np.array([[0.0, math.inf], [1.0, 0.0]]))


def test_rate_order_puts_a_large_gain_first_unless_it_is_far() -> None:
    times = line_times([0.0, 1.0, -1.0])  # both views 1 s away, 2 s from each other
    assert rate_order(times, [10, 100], overhead=0.0) == [2, 1]  # the larger gain first
    far = line_times([0.0, 1.0, -20.0])  # the large gain 20 s away, the small one 1 s away on the other side
    # [1, 2]: 10 * 1 + 100 * 22 = 2210 < [2, 1]: 100 * 20 + 10 * 41 = 2410: the near one on the way
    assert rate_order(far, [10, 100], overhead=0.0) == [1, 2]
    # a near view worth little: [2, 1]: 100 * 20 + 1 * 41 = 2041 < [1, 2]: 1 * 1 + 100 * 22 = 2201
    assert rate_order(far, [1, 100], overhead=0.0) == [2, 1]
    assert rate_order(line_times([0.0]), [], overhead=0.0) == []


def test_set_cover_counts_a_voxel_seen_twice_once() -> None:
    seen = np.zeros((4, 20), dtype=bool)
    seen[0, 0:10] = True  # 10 voxels
    seen[1, 0:9] = True  # 9 voxels, all of them view 0's
    seen[2, 10:15] = True  # 5 voxels
    seen[3, 8:17] = True  # 9 voxels: 2 of view 0's, view 2's 5 and 2 more
    views, gains = greedy_cover(seen, np.ones(4, dtype=bool), horizon=5, min_gain=0.0)
    # by raw counts view 1 (9) would come second; it adds nothing new. View 3 adds 7 (10..16), then view 2 adds 0
    assert views == [0, 3]
    assert gains == [10, 7]
    assert sum(gains) == int(seen.any(axis=0).sum())  # every voxel counted exactly once


def test_set_cover_respects_eligibility_horizon_and_min_gain() -> None:
    seen = np.zeros((3, 10), dtype=bool)
    seen[0, :6] = seen[1, 6:9] = seen[2, 9] = True
    allowed = np.array([False, True, True])
    assert greedy_cover(seen, allowed, horizon=5, min_gain=0.0) == ([1, 2], [3, 1])
    assert greedy_cover(seen, np.ones(3, dtype=bool), horizon=1, min_gain=0.0) == ([0], [6])
    # the coverable frontier is 10 voxels: a view adding 1 (< 20 % of 10) ends the cover
    assert greedy_cover(seen, np.ones(3, dtype=bool), horizon=5, min_gain=0.2) == ([0, 1], [6, 3])


def test_visibility_hides_frontier_behind_occupied_voxels() -> None:
    camera = Pose.look_at(np.array([0.0, 0.0, 0.0]), np.array([0.0, 0.0, 1.0]), up=np.array([0.0, -1.0, 0.0]))
    wall = np.array([[x, y, 0.5] for x in np.arange(-0.1, 0.11, 0.01) for y in np.arange(-0.1, 0.11, 0.01)])
    frontier = np.array(
        [
            [0.0, 0.0, 1.0],  # behind the wall
            [0.0, 0.0, 0.3],  # in front of it
            [0.3, 0.0, 1.0],  # beside the wall, in view
            [0.0, 0.0, -1.0],  # behind the camera
            [5.0, 0.0, 1.0],  # outside the image
            [0.05, 0.05, 0.505],  # on the wall, within the depth tolerance
        ]
    )
    seen = visible_frontier(frontier, wall, [camera], K, 32, 24, tolerance=0.01)
    assert seen.tolist() == [[False, True, True, False, False, True]]
    assert visible_frontier(frontier[:1], np.zeros((0, 3)), [camera], K, 32, 24, 0.01)[0, 0]  # no wall: seen
    assert not visible_frontier(frontier[:2], np.zeros((0, 3)), [camera], K, 32, 24, 0.01)[0, 0]  # frontier hides too
    assert visible_frontier(np.zeros((0, 3)), wall, [camera], K, 32, 24, 0.01).shape == (1, 0)


def dense_visible_frontier(
    frontier: np.ndarray, occluders: np.ndarray, poses: list[Pose], width: int, height: int, tolerance: float
) -> np.ndarray:
    """The reference of ``visible_frontier``: per camera a whole z-buffer image and its 3 x 3 minimum, pixel by pixel."""
    points = np.concatenate([frontier, occluders])
    seen = np.zeros((len(poses), len(frontier)), dtype=bool)
    for c, pose in enumerate(poses):
        X = points @ pose.rotation - pose.translation @ pose.rotation  # the camera frame, as visible_frontier does
        image = np.full((height, width), np.inf)
        pixels = []
        for x, y, z in X:
            if z <= 1e-6:
                pixels.append(None)
                continue
            u = (K.fx * x / z + K.cx + 0.5) * (width / K.width)
            v = (K.fy * y / z + K.cy + 0.5) * (height / K.height)
            if not (0 <= u < width and 0 <= v < height):
                pixels.append(None)
                continue
            r, q = math.floor(v), math.floor(u)
            image[r, q] = min(image[r, q], z)
            pixels.append((r, q, z))
        for f in range(len(frontier)):
            if pixels[f] is None:
                continue
            r, q, z = pixels[f]
            near = image[max(r - 1, 0) : r + 2, max(q - 1, 0) : q + 2].min()
            seen[c, f] = z <= near + tolerance
    return seen


def test_visibility_matches_a_whole_image_z_buffer_at_the_raster_edges_and_across_batches() -> None:
    # the 3 x 3 minimum is taken at each frontier voxel's pixel only; the reference takes it over the whole image
    rng = np.random.default_rng(7)
    frontier = rng.uniform(-0.15, 0.15, (120, 3))
    occluders = rng.uniform(-0.15, 0.15, (300, 3))
    poses = []
    for k in range(60):  # more than one batch of cameras (CAMERAS_PER_BATCH = 16), the last one short
        azimuth, elevation = 2 * math.pi * k / 60, 0.2 + 0.8 * (k % 5) / 5
        eye = 0.35 * np.array([math.cos(azimuth) * math.cos(elevation), math.sin(azimuth) * math.cos(elevation), 0])
        eye[2] = 0.35 * math.sin(elevation)
        poses.append(Pose.look_at(eye, np.zeros(3)))  # close enough that the cloud fills the image to its edges
    seen = visible_frontier(frontier, occluders, poses, K, 32, 24, tolerance=0.01)
    assert np.array_equal(seen, dense_visible_frontier(frontier, occluders, poses, 32, 24, 0.01))
    assert 0 < seen.sum() < seen.size  # some hidden, some seen


def test_the_tour_planner_is_registered_and_validates_its_settings() -> None:
    assert "tour" in evaluator_names()
    with pytest.raises(ValueError, match=r"^tour\.horizon:"):
        TourConfig(horizon=0)
    with pytest.raises(ValueError, match=r"^tour\.order:"):
        PlannerConfig.from_dict({"tour": {"order": "nearest"}})


def test_a_tour_plan_in_the_simulated_cell_orders_its_cover_by_move_time() -> None:
    from devices.builtins import make_builtin
    from devices.config import CellConfig
    from devices.sim import make_sim_cell

    cell = make_sim_cell(make_builtin("l-block"), cell_config=CellConfig(kinematics="reach_sphere"))
    planner = Planner(PlannerConfig().replace(tour={"opening": "none"}), evaluator="tour")  # the cover at once
    planner.integrate(cell.capture())
    plan = planner.plan(reachable=cell.is_reachable, move_times=cell.move_times)
    tour = plan.tour
    assert tour is not None and plan.best_index == tour.views[0]
    assert len(set(tour.views)) == len(tour.views) >= 2
    assert all(plan.scores[i].eligible for i in tour.views)
    assert all(g > 0 for g in tour.gains)
    times = cell.move_times(plan.candidates, list(tour.views))  # states 1..K in tour order
    assert tour.seconds[-1] == pytest.approx(path_seconds(times, list(range(1, len(tour.views) + 1))))
    assert np.all(np.diff(tour.seconds) > 0)
    assert plan.move_costs is not None and np.isfinite(plan.move_costs[tour.views[0]])
