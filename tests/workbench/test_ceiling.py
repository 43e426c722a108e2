"""The reachable-coverage ceiling without rendering: agreement with the render-based reference,
hand-checkable single views, the cache."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from devices.builtins import resolve_model
from devices.config import CameraConfig, CellConfig
from devices.mesh import turned_about_plate_axis
from devices.sim import make_sim_cell
from planner.config import PlannerConfig
from planner.types import BoundingBox, Pose
from tests.helpers import SMALL_CAMERA  # the reference renders four times faster, the footprint still ~2 mm
from workbench.evaluation.ceiling import (
    CeilingConfig,
    OcclusionScene,
    samples_with_normals,
    seen_by_any,
    spread_order,
    view_coverage,
)
from workbench.evaluation.object_ceiling import cached_ceiling, ceiling_key, ceiling_mask, reference_mask

FEW_VIEWS = PlannerConfig().replace(candidates={"count": 30, "parallels": 4})
SAMPLES = CeilingConfig(samples=3000)


class NoReach:
    """A cell that reaches nothing (no arm, no collision model)."""

    arm = None

    def __init__(self, config: CellConfig) -> None:
        self.config = config

    def is_reachable(self, T_world_camera: Pose) -> bool:
        return False

    def set_object_box(self, bbox: BoundingBox | None) -> None:
        """No collision model: nothing to do."""


@pytest.mark.parametrize("model", ["l-block", "mug"])
def test_visibility_ceiling_agrees_with_rendering(model: str) -> None:
    _, mesh = resolve_model(model)
    cell = make_sim_cell(mesh, SMALL_CAMERA, CellConfig(kinematics="reach_sphere"))
    fast, views = ceiling_mask(mesh, cell, SMALL_CAMERA, FEW_VIEWS, SAMPLES)
    ref = reference_mask(mesh, cell, FEW_VIEWS, SAMPLES)
    assert views == 30
    assert fast.shape == ref.shape == (3000,)
    agreement = float(np.mean(fast == ref))
    assert agreement >= 0.99, f"{model}: {agreement:.4f} of samples classified the same"
    assert 0.5 < fast.mean() < 1.0  # the plate hides the underside; most of the rest is seen


def test_one_view_sees_the_near_face_and_not_the_far_one() -> None:
    _, mesh = resolve_model("box")  # 0.2 x 0.14 x 0.1, centred on the plate axis
    scene = OcclusionScene(mesh, 0.2, 0.02)
    points, normals = samples_with_normals(mesh, 4000, 0)
    eye = np.array([0.6, 0.0, 0.1])  # level with the box top, on +x
    view = Pose.look_at(eye, np.array([0.0, 0.0, 0.05]))
    seen = seen_by_any(scene, points, normals, [view], CameraConfig(), 0.002)
    near = normals[:, 0] > 0.9  # the +x face
    far = normals[:, 0] < -0.9
    top = normals[:, 2] > 0.9  # seen exactly edge-on: no footprint
    assert near.sum() > 100 and far.sum() > 100
    above = points[:, 2] >= 0.002  # the planner drops points nearer the plate than its clearance
    assert seen[near & above].all()
    assert not seen[near & ~above].any() and (near & ~above).any()
    assert not seen[far].any()
    assert not seen[top].any()


def test_one_rendered_view_covers_the_near_face_and_nothing_from_a_view_away() -> None:
    _, mesh = resolve_model("box")  # 0.2 x 0.14 x 0.1, centred on the plate axis
    cell = make_sim_cell(mesh, SMALL_CAMERA, CellConfig(kinematics="reach_sphere"))
    points, normals = samples_with_normals(mesh, 4000, 0)
    box = BoundingBox(np.array([-0.15, -0.15, 0.0]), np.array([0.15, 0.15, 0.15]))
    clean = PlannerConfig().preprocess
    view = Pose.look_at(np.array([0.5, 0.0, 0.25]), np.array([0.0, 0.0, 0.05]))  # from +x, above
    depth = cell.camera.render(view)
    covered = view_coverage(depth, view, cell.camera.intrinsics, points, box, clean)
    near = (normals[:, 0] > 0.9) & (points[:, 2] > 0.01)  # the +x face, above the plate's clearance
    far = (normals[:, 0] < -0.9) & (points[:, 2] < 0.09)  # the -x face, off its top edge (within 5 mm of the top)
    assert covered.shape == (4000,) and near.sum() > 100 and far.sum() > 100
    assert covered[near].mean() > 0.95 and not covered[far].any()
    picked = np.flatnonzero(near | far)[::3]  # a subset keeps its order
    assert (view_coverage(depth, view, cell.camera.intrinsics, points[picked], box, clean) == covered[picked]).all()
    away = Pose.look_at(np.array([0.5, 0.0, 0.25]), np.array([1.5, 0.0, 0.25]))  # the camera's back to the box
    empty = view_coverage(cell.camera.render(away), away, cell.camera.intrinsics, points, box, clean)
    assert empty.shape == (4000,) and not empty.any()


def test_no_reachable_view_gives_zero() -> None:
    _, mesh = resolve_model("box")
    cell = NoReach(CellConfig(kinematics="reach_sphere"))
    covered, views = ceiling_mask(mesh, cell, SMALL_CAMERA, FEW_VIEWS, SAMPLES)
    assert views == 0
    assert not covered.any()


def test_spread_order_is_a_permutation_that_spreads() -> None:
    order = spread_order(400)
    assert sorted(order) == list(range(400))
    assert len({k // 100 for k in order[:4]}) >= 3  # the first four views come from three quarters or more
    assert spread_order(2) == [0, 1]


def test_cache_is_shared_and_keyed_by_placement(tmp_path: Path) -> None:
    _, mesh = resolve_model("l-block")
    cell = make_sim_cell(mesh, SMALL_CAMERA, CellConfig(kinematics="reach_sphere"))
    first = cached_ceiling(mesh, cell, SMALL_CAMERA, FEW_VIEWS, tmp_path, SAMPLES)
    again = cached_ceiling(mesh, cell, SMALL_CAMERA, FEW_VIEWS, tmp_path, SAMPLES)
    assert not first.cached and again.cached
    assert again.coverage == first.coverage and again.views == first.views == 30
    assert (tmp_path / f"{first.key}.json").is_file()
    turned = turned_about_plate_axis(mesh, 90.0)
    assert ceiling_key(turned, cell, SMALL_CAMERA, FEW_VIEWS, SAMPLES) != first.key
    other_cell = make_sim_cell(mesh, SMALL_CAMERA, CellConfig(arm_reach=0.7))
    assert ceiling_key(mesh, other_cell, SMALL_CAMERA, FEW_VIEWS, SAMPLES) != first.key
    (tmp_path / f"{first.key}.json").write_text("{not json")
    redone = cached_ceiling(mesh, cell, SMALL_CAMERA, FEW_VIEWS, tmp_path, SAMPLES)
    assert not redone.cached and redone.coverage == first.coverage
    assert json.loads((tmp_path / f"{first.key}.json").read_text())["coverage"] == first.coverage


@pytest.mark.parametrize(
    ("field", "value"),
    [
        ("coverage_radius", 0.0),
        ("samples", 0),
        ("probe_spacing", -1.0),
        ("occlusion_tolerance", float("nan")),
        ("probe_views", -1),
    ],
)
def test_bad_config_names_the_field(field: str, value: float) -> None:
    with pytest.raises(ValueError, match=f"ceiling.{field}"):
        CeilingConfig(**{field: value})  # type: ignore[arg-type]


def test_footprint_rule_drops_a_nearly_edge_on_surface() -> None:
    _, mesh = resolve_model("box")
    scene = OcclusionScene(mesh, 0.2, 0.02)
    points, normals = samples_with_normals(mesh, 4000, 0)
    view = Pose.look_at(np.array([0.6, 0.0, 0.105]), np.array([0.0, 0.0, 0.05]))  # 5 mm above the top's plane
    top = normals[:, 2] > 0.9  # cos ~ 0.008: one pixel spans ~10 cm of the top face
    strict = seen_by_any(scene, points, normals, [view], CameraConfig(), 0.002)
    loose = seen_by_any(scene, points, normals, [view], CameraConfig(), 0.002, CeilingConfig(max_footprint=1.0))
    assert top.sum() > 100
    assert not strict[top].any()
    assert loose[top].mean() > 0.9  # nothing hides it: only the footprint rule left it out
