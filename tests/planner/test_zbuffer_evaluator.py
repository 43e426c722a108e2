"""The projection-zbuffer evaluator in the planner loop, and the frontier ages behind zbuffer.frontier_decay."""

from __future__ import annotations

import numpy as np
import pytest

from planner import Planner, PlannerConfig
from planner.evaluators import EvaluationContext, ZBufferEvaluator, evaluator_names, make_evaluator
from planner.frontier_age import FrontierAge, ellipsoid_weights
from planner.types import DepthFrame, Ellipsoid, Intrinsics, Pose

RES = 0.01


def voxels(*ijk) -> np.ndarray:
    return (np.array(ijk, dtype=float) + 0.5) * RES


def test_ages_advance_once_per_new_frame() -> None:
    age = FrontierAge()
    a, b, c = [1, 2, 3], [-4, 0, 7], [5, 5, 5]
    assert age.update(voxels(a, b), RES, frames=1).tolist() == [0, 0]
    assert age.update(voxels(b, a, c), RES, frames=2).tolist() == [1, 1, 0]  # order does not matter
    assert age.update(voxels(b, a, c), RES, frames=2).tolist() == [1, 1, 0]  # a re-plan: unchanged
    assert age.update(voxels(c), RES, frames=3).tolist() == [1]  # a and b stopped being frontier ...
    assert age.update(voxels(a, c), RES, frames=4).tolist() == [0, 2]  # ... and a starts again at 0
    age.reset()
    assert age.update(voxels(c), RES, frames=5).tolist() == [0]
    assert age.update(np.zeros((0, 3)), RES, frames=6).tolist() == []


def test_ellipsoid_weight_is_the_mean_of_its_voxels() -> None:
    centers = voxels([0, 0, 0], [1, 0, 0], [10, 0, 0])
    w = np.array([1.0, 0.25, 0.5])
    around_two = Ellipsoid(np.array([0.01, 0.005, 0.005]), np.array([0.02, 0.01, 0.01]), np.eye(3), "frontier")
    far = Ellipsoid(np.array([0.5, 0.5, 0.5]), np.full(3, 0.01), np.eye(3), "frontier")
    occupied = Ellipsoid(np.array([0.105, 0.005, 0.005]), np.full(3, 0.01), np.eye(3), "occupied")
    out = ellipsoid_weights([around_two, far, occupied], centers, w)
    np.testing.assert_allclose(out, [0.625, 1.0, 1.0])


def sphere_frame() -> DepthFrame:
    """A depth frame of a 5 cm sphere on the plate, seen from the side."""
    rng = np.random.default_rng(0)
    d = rng.normal(size=(60000, 3))
    points = 0.05 * d / np.linalg.norm(d, axis=1, keepdims=True) + np.array([0.0, 0.0, 0.06])
    pose = Pose.look_at([0.35, 0.05, 0.2], [0.0, 0.0, 0.06])
    return DepthFrame.from_points(points, pose, Intrinsics())


def test_registered_next_to_the_paper_and_the_baselines() -> None:
    assert "projection-zbuffer" in evaluator_names() and "projection" in evaluator_names()
    assert isinstance(make_evaluator("projection-zbuffer", PlannerConfig()), ZBufferEvaluator)
    assert Planner().evaluator.name == "projection"  # the paper's stays the default


@pytest.mark.parametrize("decay", [1.0, 0.5])
def test_planner_plans_with_the_zbuffer_evaluator(decay: float) -> None:
    config = PlannerConfig().replace(candidates={"count": 24, "parallels": 3}, zbuffer={"frontier_decay": decay})
    planner = Planner(config, evaluator="projection-zbuffer")
    planner.integrate(sphere_frame())
    plan = planner.plan()
    assert len(plan.scores) == len(plan.candidates) == 24
    assert plan.best_index is not None and plan.scores[plan.best_index].eligible
    eligible = [s.score for s in plan.scores if s.eligible]
    assert plan.scores[plan.best_index].score == max(eligible) > 0
    kinds = np.array([e.kind for e in plan.ellipsoids])
    assert "frontier" in kinds and "occupied" in kinds
    for s in plan.scores:  # the breakdown adds up: V over frontier ellipsoids, hidden frontier over occupied
        assert len(s.pixels) == len(plan.ellipsoids)
        assert s.frontier == pytest.approx(s.weighted[kinds == "frontier"].sum())
        assert s.occupied == pytest.approx(s.weighted[kinds == "occupied"].sum())
        assert s.score == pytest.approx(s.frontier)
    assert plan.timings["score"] > 0 and plan.timings["cluster"] > 0
    # after one frame every frontier voxel is new (age 0): weight 1; a re-plan on the same map does not age them
    ev = planner.evaluator
    assert isinstance(ev, ZBufferEvaluator)
    ctx = EvaluationContext(
        planner.voxel_map, plan.candidates, Intrinsics(), np.ones(24, bool), np.random.default_rng()
    )
    for _ in range(2):
        np.testing.assert_array_equal(ev.frontier_weights(ctx, plan.ellipsoids), np.ones(len(plan.ellipsoids)))
