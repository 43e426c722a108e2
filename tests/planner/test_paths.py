"""The ``path`` planner: what a move sees on the way counts, once per voxel, per second of the move; a path through
the side not seen yet beats an equal-time path through the side seen; the tour's cover counts the way too."""

from __future__ import annotations

import math

import numpy as np
import pytest

from devices.builtins import make_builtin
from devices.config import CameraConfig, CellConfig
from devices.sim import make_sim_cell
from planner import CameraPath, Planner, PlannerConfig
from planner.config import PathConfig, TourConfig
from planner.evaluators import EvaluationContext, evaluator_names
from planner.paths import PathEvaluator, frames_seen, path_gains, path_rates
from planner.tour import TourEvaluator
from planner.types import Candidate, Intrinsics, Pose, VoxelClass

SMALL = PlannerConfig().replace(voxel={"resolution": 0.02}, candidates={"count": 80})
CENTER = np.array([0.0, 0.0, 0.05])
"""The small map's cube's centre."""
K = Intrinsics(width=320, height=240, fx=300.0, fy=300.0, cx=159.5, cy=119.5)


def ring_path(
    azimuths_deg: list[float], seconds: float, elevation_deg: float = 20.0, radius: float = 0.5
) -> CameraPath:
    """A camera path on a horizontal arc about ``CENTER``, looking at it, one frame per azimuth (degrees), the
    frames evenly spread over a move of ``seconds``."""
    e = math.radians(elevation_deg)
    poses = []
    for a in np.radians(azimuths_deg):
        eye = CENTER + radius * np.array([math.cos(e) * math.cos(a), math.cos(e) * math.sin(a), math.sin(e)])
        poses.append(Pose.look_at(eye, CENTER))
    times = seconds * (np.arange(len(poses)) + 1) / (len(poses) + 1)
    return CameraPath.of_poses(seconds, times, poses)


def test_path_planner_is_registered_and_its_settings_are_checked() -> None:
    assert "path" in evaluator_names()
    assert PathConfig().sample_hz == 2.5
    with pytest.raises(ValueError, match=r"path\.sample_hz"):
        PathConfig(sample_hz=0.0)
    with pytest.raises(ValueError, match=r"path\.overhead_seconds"):
        PathConfig(overhead_seconds=-1.0)
    with pytest.raises(ValueError, match=r"tour\.path_coverage"):
        TourConfig(path_coverage=1)  # type: ignore[arg-type]


def test_camera_path_checks_its_arrays() -> None:
    path = ring_path([0.0, 10.0], 2.0)
    assert len(path) == 2 and path.seconds == 2.0
    assert np.allclose(path.poses()[1].translation, path.translations[1])
    with pytest.raises(ValueError, match=r"^times: must increase"):
        CameraPath(1.0, np.array([0.5, 2.0]), path.rotations, path.translations)
    with pytest.raises(ValueError, match=r"^seconds"):
        CameraPath(math.inf, np.zeros(0), np.zeros((0, 3, 3)), np.zeros((0, 3)))
    with pytest.raises(ValueError, match=r"^rotations"):
        CameraPath(1.0, np.array([0.5]), np.zeros((2, 3, 3)), np.zeros((1, 3)))
    assert len(CameraPath.of_poses(0.5, [], [])) == 0


def test_path_gain_counts_a_voxel_seen_by_the_view_and_several_frames_once() -> None:
    views = np.zeros((2, 10), dtype=bool)
    views[0, :3] = True  # view 0 sees voxels 0..2
    views[1, 5:7] = True  # view 1 sees 5, 6
    frames = np.zeros((5, 10), dtype=bool)
    frames[0, 2:5] = True  # path 0, frame 1: 2, 3, 4 (2 the view's own)
    frames[1, 3:6] = True  # path 0, frame 2: 3, 4, 5 (3, 4 the first frame's)
    frames[2:5, 9] = True  # path 1, three frames all on voxel 9
    assert path_gains(views, frames, [2, 3]).tolist() == [6, 3]  # {0..5}; {5, 6, 9}
    assert path_gains(views, np.zeros((0, 10), dtype=bool), [0, 0]).tolist() == [3, 2]
    with pytest.raises(ValueError, match=r"^seen_frames"):
        path_gains(views, frames, [2, 2])
    rates = path_rates(np.array([6.0, 3.0, 5.0]), np.array([2.0, 0.0, math.inf]), overhead=1.0)
    assert rates[0] == pytest.approx(2.0) and rates[1] == pytest.approx(3.0) and rates[2] == -math.inf


class SmallMap:
    """A voxel map in voxel centres (what the visibility test reads): the surface of a 0.1 m cube on the plate,
    occupied, and in front of its +x face a 9 x 9 sheet of frontier voxels: the +x side is not seen yet, the -x side
    is (no frontier there)."""

    def __init__(self) -> None:
        r = 0.01
        g = np.arange(-0.045, 0.05, r)
        z = np.arange(0.005, 0.1, r)
        X, Y, Z = np.meshgrid(g, g, z, indexing="ij")
        cube = np.stack([X.ravel(), Y.ravel(), Z.ravel()], axis=1)
        shell = (np.abs(cube[:, :2]).max(axis=1) > 0.04) | (cube[:, 2] > 0.09)
        self.occupied = cube[shell]
        s = np.arange(-0.04, 0.045, r)
        S, T = np.meshgrid(s, s + 0.05, indexing="ij")
        self.frontier = np.stack([np.full(S.size, 0.055), S.ravel(), T.ravel()], axis=1)

    def centers(self, cls: VoxelClass) -> np.ndarray:
        return (
            self.frontier
            if cls == VoxelClass.FRONTIER
            else self.occupied
            if cls == VoxelClass.OCCUPIED
            else np.zeros((0, 3))
        )


def small_map_evaluator() -> tuple[PathEvaluator, list[Candidate], list]:
    """The path evaluator after evaluating two candidates at the same view straight above the cube (both see the
    same frontier), with its scores."""
    top = Pose.look_at(np.array([0.0, 0.0, 0.45]), CENTER, up=np.array([1.0, 0.0, 0.0]))
    candidates = [Candidate(i, top, math.radians(90.0), 0.0, 0, 0) for i in range(2)]
    evaluator = PathEvaluator(PlannerConfig())
    ctx = EvaluationContext(SmallMap(), tuple(candidates), K, np.ones(2, dtype=bool), np.random.default_rng(0))  # type: ignore[arg-type]
    scores = evaluator.evaluate(ctx).scores
    return evaluator, candidates, list(scores)


UNSEEN_WAY = [-20.0, -10.0, 0.0, 10.0, 20.0]
"""Azimuths (deg) of a sweep past the +x side (the frontier sheet's)."""
SEEN_WAY = [160.0, 170.0, 180.0, 190.0, 200.0]
"""Azimuths of a sweep past the -x side, seen already."""


def test_a_path_through_unseen_surface_beats_an_equal_time_path_through_seen_surface() -> None:
    evaluator, candidates, scores = small_map_evaluator()
    sheet = len(evaluator.last_frontier)
    assert sheet == 81
    view = int(evaluator.last_seen[0].sum())
    assert view == int(evaluator.last_seen[1].sum()) < sheet // 4  # from above: the sheet's top row at most
    tour = evaluator.config.tour
    tolerance = tour.depth_tolerance_voxels * evaluator.config.voxel.resolution
    unseen, seen = ring_path(UNSEEN_WAY, 3.0), ring_path(SEEN_WAY, 3.0)
    frames = frames_seen(
        evaluator.last_frontier, evaluator.last_occluders, [unseen, seen], K, tour.width, tour.height, tolerance
    )
    assert frames[:5].any(axis=0).sum() == sheet  # the sweep past +x sees every frontier voxel
    assert frames[5:].sum() == 0  # the cube hides the sheet from the -x side
    assert path_gains(evaluator.last_seen, frames, [5, 5]).tolist() == [sheet, view]
    for routes in ({0: seen, 1: unseen}, {0: unseen, 1: seen}):  # either candidate, whichever way is unseen

        def move_paths(cands, indices, hz, routes=routes):
            assert hz == evaluator.config.path.sample_hz
            return [routes[int(i)] for i in indices]

        best, plan = evaluator.choose(scores, candidates, candidates[0].T_world_camera, None, move_paths=move_paths)
        assert best is not None and best == next(i for i, r in routes.items() if r is unseen)
        assert plan is not None and plan.method == "path" and plan.gains == (sheet,) and plan.seconds == (3.0,)
        assert evaluator.last_rates[best] == pytest.approx(sheet / (3.0 + evaluator.config.path.overhead_seconds))


class UnknownMap(SmallMap):
    """The small map with no frontier left and, beyond the cube's +x face, a slab of unknown voxels (the space behind
    the seen rim that no frame has looked into)."""

    def __init__(self) -> None:
        super().__init__()
        r = 0.01
        X, Y, Z = np.meshgrid(np.arange(0.065, 0.1, r), np.arange(-0.045, 0.05, r), np.arange(0.005, 0.1, r))
        self.unknown = np.stack([X.ravel(), Y.ravel(), Z.ravel()], axis=1)
        self.frontier = np.zeros((0, 3))

    def centers(self, cls: VoxelClass) -> np.ndarray:
        return self.unknown if cls == VoxelClass.UNKNOWN else super().centers(cls)


def test_the_path_gain_counts_the_unknown_space_a_sweep_looks_into() -> None:
    """With no frontier to tell two equal-time sweeps apart, the one that looks into the unknown space behind the
    cube's +x face wins; the one past the seen -x side sees none of it (the cube hides it); stride 0 counts the
    frontier alone (a tie, broken by the lower index)."""
    top = Pose.look_at(np.array([0.0, 0.0, 0.45]), CENTER, up=np.array([1.0, 0.0, 0.0]))
    candidates = [Candidate(i, top, math.radians(90.0), 0.0, 0, 0) for i in range(2)]
    for stride in (2, 0):
        evaluator = PathEvaluator(PlannerConfig().replace(path={"unknown_stride": stride}))
        ctx = EvaluationContext(UnknownMap(), tuple(candidates), K, np.ones(2, dtype=bool), np.random.default_rng(0))  # type: ignore[arg-type]
        scores = list(evaluator.evaluate(ctx).scores)
        sampled = len(evaluator.last_unknown)
        voxels = UnknownMap().unknown
        assert sampled == (0 if stride == 0 else int(np.all(np.floor(voxels / 0.01) % 2 == 0, axis=1).sum()))
        routes = {0: ring_path(SEEN_WAY, 3.0), 1: ring_path(UNSEEN_WAY, 3.0)}
        best, _ = evaluator.choose(
            scores, candidates, top, None, move_paths=lambda c, idx, hz, routes=routes: [routes[int(i)] for i in idx]
        )
        if stride:  # the way past +x sees the whole slab; the other only what the view above sees of its top
            assert sampled > 20 and best == 1
            assert evaluator.last_gains[1] == sampled and evaluator.last_gains[0] < 0.6 * sampled
        else:
            assert evaluator.last_gains == {0: 0, 1: 0}


def test_without_the_way_there_the_rate_is_the_views_own_per_second() -> None:
    evaluator, candidates, scores = small_map_evaluator()
    times = np.array([[0.0, 4.0, 1.0], [4.0, 0.0, 3.0], [1.0, 3.0, 0.0]])  # candidate 1 is the nearer

    def move_times(cands, indices, exact=False):
        return times

    best, plan = evaluator.choose(scores, candidates, candidates[0].T_world_camera, move_times)
    assert best == 1 and plan is not None and plan.seconds == (1.0,)
    view = int(evaluator.last_seen[1].sum())
    assert evaluator.last_rates == pytest.approx({0: view / 5.0, 1: view / 2.0})
    unreachable = np.where(np.eye(3, dtype=bool), 0.0, math.inf)
    assert evaluator.choose(
        scores, candidates, candidates[0].T_world_camera, lambda c, i, exact=False: unreachable
    ) == (
        None,
        None,
    )
    assert evaluator.last_move_seconds == {0: math.inf, 1: math.inf}


def test_a_plan_with_the_cells_paths_and_the_tour_counting_the_way() -> None:
    """The whole plan with a real (reach-sphere) cell's paths: the chosen move's path has frames and the plan
    names its seconds; the tour with ``path_coverage`` asks the cell for the paths of its pool."""
    cell = make_sim_cell(make_builtin("box"), CameraConfig(), CellConfig(kinematics="reach_sphere"), seed=0)
    cell.move_to(cell.initial_pose())
    planner = Planner(SMALL, "path")
    planner.integrate(cell.capture())
    plan = planner.plan(reachable=cell.is_reachable, move_times=cell.move_times, move_paths=cell.move_paths)
    evaluator = planner.evaluator
    assert isinstance(evaluator, PathEvaluator)
    assert plan.best_index is not None and plan.tour is not None and plan.tour.method == "path"
    path = evaluator.last_paths[plan.best_index]
    assert len(path) == math.ceil(path.seconds * 2.5) - 1  # frames at 2.5 Hz strictly inside the move
    assert plan.tour.seconds[0] == pytest.approx(path.seconds)
    assert plan.move_costs is not None and plan.move_costs[plan.best_index] == pytest.approx(path.seconds)
    asked: list[int] = []

    def counted(cands, indices, hz):
        asked.extend(indices)
        return cell.move_paths(cands, indices, hz)

    tour = Planner(
        SMALL.replace(tour={"opening": "none", "path_coverage": True}), "tour"
    )  # the ring's opening views come first otherwise
    tour.integrate(cell.capture())
    tour.plan(reachable=cell.is_reachable, move_times=cell.move_times, move_paths=counted)
    assert asked  # the cover counted the way there
    assert isinstance(tour.evaluator, TourEvaluator)
    off = Planner(SMALL.replace(tour={"opening": "none", "path_coverage": False}), "tour")
    off.integrate(cell.capture())
    asked.clear()
    off.plan(reachable=cell.is_reachable, move_times=cell.move_times, move_paths=counted)
    assert not asked
