"""The planner facade: Algorithm 1's state, atomic integration, partitions, termination."""

from __future__ import annotations

import numpy as np
import pytest

from devices.builtins import make_builtin
from devices.config import CameraConfig, CellConfig
from devices.sim import make_sim_cell
from planner import Planner, PlannerConfig, VoxelClass
from planner.types import DepthFrame, Pose

SMALL = PlannerConfig().replace(
    voxel={"resolution": 0.02},
    candidates={"count": 80},
    cluster={"t_min": 2, "t_max": 6},
    termination={"max_views": 4},
)


@pytest.fixture(scope="module")
def cell():
    return make_sim_cell(make_builtin("l-block"), CameraConfig(), CellConfig(kinematics="reach_sphere"), seed=0)


def first_frame(cell) -> DepthFrame:
    cell.move_to(cell.initial_pose())
    return cell.capture()


def test_plan_before_any_frame_is_refused() -> None:
    with pytest.raises(ValueError, match="no frame has been integrated"):
        Planner(SMALL).plan()


def test_bad_frames_leave_state_unchanged(cell) -> None:
    planner = Planner(SMALL)
    frame = first_frame(cell)
    planner.integrate(frame)
    classes, cloud, views = planner.voxel_map.classes.copy(), planner.cloud.copy(), list(planner.views)
    empty = DepthFrame(np.zeros_like(frame.depth), frame.T_world_camera, frame.intrinsics)
    with pytest.raises(ValueError, match="empty frame"):
        planner.integrate(empty)
    # every return far behind the object: nothing is left after cropping
    far = DepthFrame(
        np.where(frame.depth > 0, np.float32(5.0), np.float32(0.0)), frame.T_world_camera, frame.intrinsics
    )
    with pytest.raises(ValueError, match="no point left"):
        planner.integrate(far)
    assert np.array_equal(planner.voxel_map.classes, classes)
    assert np.array_equal(planner.cloud, cloud) and planner.views == views


def test_loop_respects_partitions_and_terminates(cell) -> None:
    planner = Planner(SMALL)
    pose = cell.initial_pose()
    sectors_visited = []
    for _ in range(SMALL.termination.max_views):
        cell.move_to(pose)
        planner.integrate(cell.capture())
        plan = planner.plan(reachable=cell.is_reachable)
        best = plan.best
        assert best is not None and best.index == plan.best_index
        # only unscanned sectors next to the scanned arc, until all are scanned
        if len(plan.scanned_sectors) < SMALL.partitions.sectors:
            assert best.sector in plan.eligible_sectors
            assert best.sector not in plan.scanned_sectors
            for s in plan.eligible_sectors:
                assert (s - 1) % 4 in plan.scanned_sectors or (s + 1) % 4 in plan.scanned_sectors
        eligible = [s for s in plan.scores if s.eligible]
        assert plan.scores[best.index].score == max(s.score for s in eligible)
        sectors_visited.append(best.sector)
        pose = best.T_world_camera
    assert planner.terminated == "max_views"
    assert plan.terminated == "max_views"
    assert planner.iteration == 4
    counts = planner.point_counts
    assert counts == sorted(counts) and counts[-1] > counts[0]
    assert planner.voxel_map.count(VoxelClass.OCCUPIED) > 0


def test_growth_threshold_stops_the_scan(cell) -> None:
    cfg = SMALL.replace(termination={"growth_threshold": 10.0, "max_views": 10})
    planner = Planner(cfg)
    frame = first_frame(cell)
    planner.integrate(frame)
    assert planner.terminated is None
    planner.integrate(frame)  # the same view again: no growth
    assert planner.terminated == "growth"


def test_rays_ending_on_the_plate_carve_free_space(monkeypatch: pytest.MonkeyPatch) -> None:
    """Departure (docs/method.md): plate hits count as free space, so far less frontier is left on the plate."""
    mug_cell = make_sim_cell(make_builtin("mug"), CameraConfig(), CellConfig(kinematics="reach_sphere"), seed=0)
    frames = []
    for azimuth in (np.pi, np.pi / 2, 0.0, 1.5 * np.pi):  # four views round the mug, 20 degrees up
        eye = np.array([0.0, 0.0, 0.08]) + 0.5 * np.array(
            [np.cos(0.35) * np.cos(azimuth), np.cos(0.35) * np.sin(azimuth), np.sin(0.35)]
        )
        mug_cell.move_to(Pose.look_at(eye, [0.0, 0.0, 0.08]))
        frames.append(mug_cell.capture())
    cfg = PlannerConfig().replace(registration={"enabled": False})

    planner = Planner(cfg)
    carved = planner._plate_as_free_space(frames[0])
    on_plate = frames[0].points_world[:, 2] < 0.002
    assert on_plate.sum() > 1000  # the camera sees plenty of plate round the mug
    assert np.count_nonzero(carved.depth) == np.count_nonzero(frames[0].depth) - on_plate.sum()
    kept = carved.depth > 0
    assert np.array_equal(carved.depth[kept], frames[0].depth[kept])

    def bottom_frontier(p: Planner) -> int:
        for frame in frames:
            p.integrate(frame)
        return int(np.count_nonzero(p.voxel_map.centers(VoxelClass.FRONTIER)[:, 2] < 0.01))

    ours = bottom_frontier(planner)
    monkeypatch.setattr(Planner, "_plate_as_free_space", lambda self, f, plate=None: f)
    literal = bottom_frontier(Planner(cfg))
    assert literal >= 20  # plate hits taken literally: a ring of frontier on the plate that no view clears
    assert ours <= literal // 4


def test_revisit_radius_makes_candidates_near_taken_views_ineligible(cell) -> None:
    frame = first_frame(cell)
    plans = {}
    for deg in (0.0, 20.0):
        planner = Planner(SMALL.replace(partitions={"revisit_deg": deg}))
        planner.integrate(frame)
        plan = planner.plan()
        center = plan.hemisphere_center
        taken = frame.T_world_camera.translation - center
        taken /= np.linalg.norm(taken)
        angles = np.array(
            [
                np.arccos(np.clip(np.dot(taken, (c.position - center) / np.linalg.norm(c.position - center)), -1, 1))
                for c in plan.candidates
            ]
        )
        plans[deg] = (plan, angles)
    wide, angles = plans[20.0]
    near = angles < np.radians(20.0)
    assert near.sum() >= 3
    assert not any(s.eligible for s, n in zip(wide.scores, near, strict=True) if n)
    narrow, _ = plans[0.0]
    # 0 (the paper's rule) only removes the view itself: more candidates near it stay eligible
    assert sum(s.eligible for s in narrow.scores) > sum(s.eligible for s in wide.scores)


def test_default_revisit_radius_is_30_degrees() -> None:
    """The departure of docs/method.md: views within 30 degrees of a taken one are not proposed."""
    assert PlannerConfig().partitions.revisit_deg == 30.0


def test_revisit_radius_that_would_leave_nothing_falls_back_to_the_view_itself(cell) -> None:
    frame = first_frame(cell)
    eligible = {}
    for deg in (0.0, 179.0):
        planner = Planner(SMALL.replace(partitions={"revisit_deg": deg}))
        planner.integrate(frame)
        eligible[deg] = [s.eligible for s in planner.plan().scores]
    # 179 degrees from the first view covers the whole hemisphere: only the half spacing applies
    assert any(eligible[0.0])
    assert eligible[179.0] == eligible[0.0]


def test_content_aim_builds_the_sphere_about_the_object_seen_not_all_of_b(cell) -> None:
    """After the first frame B has grown along the view (paper §III-C) far past the object; with
    ``candidates.aim = "content"`` the sphere is about the box of the OCCUPIED and FRONTIER voxels instead: a
    smaller radius, a centre on the object. The paper's aim (the default) keeps B."""
    from planner.candidates import sphere_radius

    frame = first_frame(cell)
    paper, content = Planner(SMALL), Planner(SMALL.replace(candidates={"aim": "content"}))
    for planner in (paper, content):
        planner.integrate(frame)
    b = paper.voxel_map.bbox
    assert b is not None
    np.testing.assert_array_equal(paper.candidate_box().lower, b.lower)
    np.testing.assert_array_equal(paper.candidate_box().upper, b.upper)
    box = content.candidate_box()
    res = content.voxel_map.resolution
    seen = np.concatenate(
        [content.voxel_map.centers(VoxelClass.OCCUPIED), content.voxel_map.centers(VoxelClass.FRONTIER)]
    )
    np.testing.assert_allclose(box.lower, seen.min(axis=0) - res / 2, atol=1e-9)
    np.testing.assert_allclose(box.upper, seen.max(axis=0) + res / 2, atol=1e-9)
    assert np.all(box.lower >= b.lower - 1e-9) and np.all(box.upper <= b.upper + 1e-9)
    assert box.diagonal < 0.8 * b.diagonal  # B's growth along the view is not in it
    plan = content.plan()
    np.testing.assert_allclose(plan.hemisphere_center, box.center)
    assert plan.hemisphere_radius == pytest.approx(sphere_radius(SMALL.candidates, 0.5 * box.diagonal))
    np.testing.assert_allclose(paper.plan().hemisphere_center, b.center)


def test_content_aim_is_held_while_the_box_moves_by_at_most_aim_hold_voxels(cell) -> None:
    """After each frame the content aim keeps the box it was built about while no face of the new content box moved
    more than ``aim_hold_voxels`` voxels from it (``held_aim``, step by step), else takes the new box; 0 follows every
    change. Three frames of the l-block from views 120 deg apart (1 cm voxels): the second moves its content box by a
    voxel (the test fails if it does not), so with 1 the first frame's box is kept and with 0 it is not."""
    from planner.candidates import held_aim

    frames = []
    for azimuth in (0.0, 120.0, 240.0):
        eye = np.array([0.45 * np.cos(np.radians(azimuth)), 0.45 * np.sin(np.radians(azimuth)), 0.3])
        pose = Pose.look_at(eye, np.array([0.0, 0.0, 0.05]))
        cell.move_to(pose)
        frames.append(cell.capture())
    res = 0.01
    config = SMALL.replace(voxel={"resolution": res})
    planners = {n: Planner(config.replace(candidates={"aim": "content", "aim_hold_voxels": n})) for n in (0, 1, 50)}
    boxes: dict[int, list] = {n: [] for n in planners}
    contents = []
    for frame in frames:
        for n, planner in planners.items():
            planner.integrate(frame)
            boxes[n].append(planner.candidate_box())
        contents.append(planners[0]._content_box())

    def moved(a, b) -> float:
        return float(max(np.abs(b.lower - a.lower).max(), np.abs(b.upper - a.upper).max()))

    for n in planners:  # the content box itself does not depend on the hold
        np.testing.assert_array_equal(planners[n]._content_box().upper, contents[-1].upper)
    assert round(moved(contents[0], contents[1]) / res) == 1  # the second view moves a face by a voxel
    for i, content in enumerate(contents):  # 0: the content box of every frame
        np.testing.assert_array_equal(boxes[0][i].lower, content.lower)
        np.testing.assert_array_equal(boxes[0][i].upper, content.upper)
    expected = None
    for i, content in enumerate(contents):  # 1: the rule step by step, never more than 1.5 voxels off
        expected = held_aim(expected, content, 1.5 * res)
        np.testing.assert_array_equal(boxes[1][i].lower, expected.lower)
        np.testing.assert_array_equal(boxes[1][i].upper, expected.upper)
        assert moved(boxes[1][i], content) <= 1.5 * res
    assert boxes[1][1] is boxes[1][0] and moved(boxes[1][1], contents[1]) > 0.5 * res  # held though it moved
    for i in range(3):  # 50 voxels: the first frame's box throughout
        assert boxes[50][i] is boxes[50][0]
    plan = planners[1].plan()
    np.testing.assert_allclose(plan.hemisphere_center, boxes[1][0].center)  # the plan is built about the held box
    assert moved(boxes[1][0], contents[-1]) > 0.5 * res
