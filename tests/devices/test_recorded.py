"""Recorded view sets: the Stanford range-scan reader (on small synthetic scans written here), our folder format
(a simulated session exported and read back), the recorded cell and a planner choosing among its views."""

from __future__ import annotations

import json
import math
from pathlib import Path

import numpy as np
import pytest
import trimesh
from scipy.spatial.transform import Rotation

from devices.builtins import make_builtin
from devices.config import CellConfig
from devices.recorded import (
    RecordedCell,
    read_conf,
    read_range_ply,
    read_stanford,
    read_view_folder,
    scanner_direction,
    write_view_folder,
)
from devices.sim import make_sim_cell
from planner import Planner
from planner.config import PlannerConfig
from planner.types import Intrinsics
from tests.helpers import orbit_view
from workbench.evaluation.accuracy import accuracy
from workbench.evaluation.recorded import fewest_views, greedy_order, recorded_truth, run_recorded

RADIUS = 0.05
STEP = 0.002
SMALL = Intrinsics(width=160, height=120, fx=180.0, fy=180.0, cx=79.5, cy=59.5)


def sphere_scan(path: Path, extra_lines: int = 0) -> np.ndarray:
    """Write an orthographic range scan of a sphere (radius RADIUS, centre at the scan frame's origin) seen from
    +z: a grid of STEP-spaced columns (x) and rows (y), a vertex where the ray hits. Returns the (N, 3) points."""
    n = int(2.4 * RADIUS / STEP)
    coords = (np.arange(n) - (n - 1) / 2) * STEP
    points, cells = [], []
    for y in coords:
        for x in coords:
            r2 = RADIUS**2 - x * x - y * y
            if r2 > (0.2 * RADIUS) ** 2:  # the grazing rim gives no return, as a scanner's does
                cells.append(f"1 {len(points)}")
                points.append((x, y, math.sqrt(r2)))
            else:
                cells.append("0")
    header = [
        "ply",
        "format ascii 1.0",
        f"obj_info num_cols {n}",
        f"obj_info num_rows {n}",
        f"element vertex {len(points)}",
        "property float x",
        "property float y",
        "property float z",
        f"element range_grid {n * n + extra_lines}",
        "property list uchar int vertex_indices",
        "end_header",
    ]
    body = [f"{x:.7f} {y:.7f} {z:.7f}" for x, y, z in points] + cells
    path.write_text("\n".join(header + body) + "\n", encoding="ascii")
    return np.array(points)


TURNS = {"front.ply": (0.0, 0.0), "side.ply": (90.0, 0.0), "top.ply": (0.0, 70.0)}
"""Scan name: (turn about y, tilt about x) in degrees: where each scan's scanner stood, about the sphere."""
CENTRE_REF = np.array([0.01, 0.05, -0.02])
"""The sphere's centre in the conf's reference frame (y-up)."""


def stanford_folder(root: Path) -> dict[str, Rotation]:
    """Three synthetic scans of one sphere, a .conf registering them (quaternions to be inverted) and a reference
    mesh. Returns each scan's R_ref_scan."""
    lines = ["camera 0 0 0 0 0 0 1"]
    rotations = {}
    for name, (turn, tilt) in TURNS.items():
        sphere_scan(root / name)
        R_ref_scan = Rotation.from_euler("yx", [turn, -tilt], degrees=True)
        rotations[name] = R_ref_scan
        q = R_ref_scan.inv().as_quat()  # the conf's q is applied inverted: p_ref = R(q)^-1 p_scan + t
        t = CENTRE_REF
        lines.append(f"bmesh {name} {t[0]} {t[1]} {t[2]} {q[0]} {q[1]} {q[2]} {q[3]}")
    (root / "set.conf").write_text("\n".join(lines) + "\n")
    reference = trimesh.creation.icosphere(subdivisions=4, radius=RADIUS)
    reference.apply_translation(CENTRE_REF)
    reference.export(str(root / "sphere_zipper.ply"))
    return rotations


def test_range_ply_reader_keeps_the_grid(tmp_path: Path) -> None:
    points = sphere_scan(tmp_path / "s.ply")
    scan = read_range_ply(tmp_path / "s.ply")
    assert scan.points.shape == points.shape
    np.testing.assert_allclose(scan.points, points, atol=1e-7)
    assert int((scan.grid >= 0).sum()) == len(points)
    # the grid maps (row, col) to the vertex at (x(col), y(row))
    rows, cols = np.nonzero(scan.grid >= 0)
    n = scan.grid.shape[1]
    np.testing.assert_allclose(scan.points[scan.grid[rows, cols], 0], (cols - (n - 1) / 2) * STEP, atol=1e-6)


def test_scanner_direction_is_the_range_axis_facing_the_scanner(tmp_path: Path) -> None:
    sphere_scan(tmp_path / "s.ply")
    scan = read_range_ply(tmp_path / "s.ply")
    np.testing.assert_allclose(scanner_direction(scan), [0, 0, 1], atol=1e-6)
    turned = type(scan)(scan.points * np.array([-1, 1, -1]), scan.grid, scan.info)  # a half turn about y
    np.testing.assert_allclose(scanner_direction(turned), [0, 0, -1], atol=1e-6)
    # given the object's centre, the scanner is on the side of the centre the points are
    np.testing.assert_allclose(scanner_direction(scan, np.array([0, 0, 0.0])), [0, 0, 1], atol=1e-6)
    np.testing.assert_allclose(scanner_direction(scan, np.array([0, 0, 0.2])), [0, 0, -1], atol=1e-6)


def test_stanford_reader_registers_places_and_derives_viewpoints(tmp_path: Path) -> None:
    rotations = stanford_folder(tmp_path)
    recorded = read_stanford(tmp_path, distance=0.4, intrinsics=SMALL)
    assert [v.name for v in recorded.views] == ["front", "side", "top"]
    assert recorded.reference is not None
    lower, upper = recorded.reference.bounds
    assert lower[2] == pytest.approx(0.0, abs=1e-9)  # on the plate
    np.testing.assert_allclose(0.5 * (lower[:2] + upper[:2]), 0.0, atol=1e-9)  # on the turntable axis
    centre = 0.5 * (lower + upper)
    for view in recorded.views:
        # registered by the inverted quaternions, every scan lies on the reference sphere
        radii = np.linalg.norm(view.points_world - centre, axis=1)
        np.testing.assert_allclose(radii, RADIUS, atol=2e-3 * RADIUS)
        # the camera stands on the scan's +z (its scanner's side), 0.4 m from the scan's centre, looking back
        R_ref_scan = rotations[f"{view.name}.ply"].as_matrix()
        up_z = np.array([[1.0, 0, 0], [0, 0, -1], [0, 1, 0]])  # y-up -> z-up
        expected = up_z @ R_ref_scan @ np.array([0.0, 0.0, 1.0])
        offset = view.T_world_sensor.translation - centre
        assert offset @ expected / np.linalg.norm(offset) > math.cos(math.radians(8))
        assert view.T_world_sensor.rotation[:, 2] @ expected == pytest.approx(-1.0, abs=1e-9)
    top = recorded.views[2].T_world_sensor.translation
    assert math.degrees(math.atan2(top[2] - centre[2], math.hypot(*(top[:2] - centre[:2])))) > 45


def test_conf_quaternion_is_inverted_and_bad_lines_are_named(tmp_path: Path) -> None:
    q = Rotation.from_euler("y", 30, degrees=True).as_quat()
    (tmp_path / "a.conf").write_text(f"bmesh s.ply 1 2 3 {q[0]} {q[1]} {q[2]} {q[3]}\n")
    pose = read_conf(tmp_path / "a.conf")["s.ply"]
    np.testing.assert_allclose(pose.rotation, Rotation.from_quat(q).inv().as_matrix(), atol=1e-12)
    np.testing.assert_allclose(pose.translation, [1, 2, 3])
    (tmp_path / "b.conf").write_text("bmesh s.ply 1 2 3 0 0 0\n")
    with pytest.raises(ValueError, match=r"b.conf:1"):
        read_conf(tmp_path / "b.conf")


def test_stanford_reader_rejects_a_malformed_scan(tmp_path: Path) -> None:
    stanford_folder(tmp_path)
    sphere_scan(tmp_path / "side.ply", extra_lines=5)
    with pytest.raises(ValueError, match=r"side.ply: range_grid has"):
        read_stanford(tmp_path, intrinsics=SMALL)
    (tmp_path / "side.ply").unlink()
    with pytest.raises(ValueError, match=r"side.ply.*not found"):
        read_stanford(tmp_path, intrinsics=SMALL)


def test_recorded_cell_offers_only_its_views_and_a_planner_chooses_among_them(tmp_path: Path) -> None:
    stanford_folder(tmp_path)
    recorded = read_stanford(tmp_path, distance=0.4, intrinsics=SMALL)
    cell = RecordedCell(recorded)
    assert cell.candidate_poses() == recorded.poses
    assert not cell.is_reachable(orbit_view((0, 0, 0.05), 30, 10))
    truth = recorded_truth(recorded)
    run = run_recorded(recorded, "projection", PlannerConfig(), truth, surface=False)
    assert sorted(run.order) == ["front", "side", "top"]  # every view once, none twice
    assert run.order[0] == "front"  # the cell's first view
    assert run.coverage == sorted(run.coverage)
    # the last plan's candidates were the recorded views, not the hemisphere's 400
    planner = Planner(PlannerConfig())
    planner.integrate(recorded.frame(0))
    from workbench.planning import plan_in

    plan = plan_in(cell, planner)
    assert len(plan.candidates) == 3
    assert plan.best is not None and plan.best_index in (1, 2)  # the view taken is not offered again


def test_oracle_order_and_fewest_views() -> None:
    cover = np.zeros((4, 10), dtype=bool)
    cover[0, :4] = True
    cover[1, 3:7] = True
    cover[2, :6] = True
    cover[3, 6:] = True
    assert greedy_order(cover) == [2, 3, 0, 1]
    assert greedy_order(cover, first=1) == [1, 0, 3, 2]  # ties: the lower index
    k, subset = fewest_views(cover, 1.0) or (0, ())
    assert (k, subset) == (2, (2, 3))


def test_a_simulated_session_exported_to_the_folder_format_reads_back_with_the_same_coverage(tmp_path: Path) -> None:
    mesh = make_builtin("mug", size=0.12)
    cell = make_sim_cell(mesh, cell_config=CellConfig(kinematics="reach_sphere"))
    frames = []
    for azimuth, elevation in ((0, 30), (120, 20), (240, 45)):
        pose = orbit_view((0, 0, 0.05), elevation, azimuth)
        cell.move_to(pose)
        frames.append(cell.capture())
    write_view_folder(tmp_path / "set", frames, reference=mesh, name="mug")
    manifest = json.loads((tmp_path / "set" / "views.json").read_text())
    assert manifest["format"] == "nbv-views" and len(manifest["views"]) == 3
    recorded = read_view_folder(tmp_path / "set")
    assert recorded.reference is not None and len(recorded.views) == 3
    truth = recorded_truth(recorded)
    per_view = []
    for source in (frames, [recorded.frame(i) for i in range(3)]):
        planner = Planner(PlannerConfig())
        coverage = []
        for frame in source:
            planner.integrate(frame)
            coverage.append(accuracy(truth, planner.cloud).recall_5mm)
        per_view.append(coverage)
    assert per_view[0] == per_view[1]
    assert 0.2 < per_view[0][0] < per_view[0][-1]


def test_folder_format_errors_name_the_field(tmp_path: Path) -> None:
    k = {"width": 4, "height": 3, "fx": 3.0, "fy": 3.0, "cx": 1.5, "cy": 1.0}
    np.save(tmp_path / "a.npy", np.ones((3, 4), dtype=np.float32))
    view = {"name": "a", "depth": "a.npy", "T_world_camera": np.eye(4).tolist()}
    (tmp_path / "views.json").write_text(json.dumps({"format": "nbv-views", "intrinsics": k, "views": [view]}))
    assert read_view_folder(tmp_path).views[0].points_sensor.shape == (12, 3)
    bad = dict(view, T_world_camera=[[1, 0, 0], [0, 1, 0], [0, 0, 1]])
    (tmp_path / "views.json").write_text(json.dumps({"format": "nbv-views", "intrinsics": k, "views": [bad]}))
    with pytest.raises(ValueError, match=r"views\[0\]: T_world_camera"):
        read_view_folder(tmp_path)
    np.save(tmp_path / "a.npy", np.ones((2, 4), dtype=np.float32))
    (tmp_path / "views.json").write_text(json.dumps({"format": "nbv-views", "intrinsics": k, "views": [view]}))
    with pytest.raises(ValueError, match=r"views\[0\]: depth image"):
        read_view_folder(tmp_path)
    escape = dict(view, depth="../x.npy")
    (tmp_path / "views.json").write_text(json.dumps({"format": "nbv-views", "intrinsics": k, "views": [escape]}))
    with pytest.raises(ValueError, match=r"not a file inside"):
        read_view_folder(tmp_path)


def test_trim_edges_drops_the_rim_of_what_the_scanner_saw(tmp_path: Path) -> None:
    from devices.recorded import trim_edges

    sphere_scan(tmp_path / "s.ply")
    scan = read_range_ply(tmp_path / "s.ply")
    trimmed = trim_edges(scan, 2)
    rows, cols = np.nonzero(trimmed.grid >= 0)
    # what is left sits where the scan had returns 2 cells around, and the grid still maps to the same points
    np.testing.assert_allclose(trimmed.points[trimmed.grid[rows, cols]], scan.points[scan.grid[rows, cols]])
    for dr in (-2, 0, 2):
        for dc in (-2, 0, 2):
            assert np.all(scan.grid[rows + dr, cols + dc] >= 0)
    radius = np.hypot(trimmed.points[:, 0], trimmed.points[:, 1]).max()
    assert radius < np.hypot(scan.points[:, 0], scan.points[:, 1]).max() - 1.5 * STEP
    assert trim_edges(scan, 0) is scan


def test_given_candidate_poses_keep_their_order_and_sectors() -> None:
    from planner.candidates import candidates_from_poses
    from planner.config import PartitionConfig
    from planner.types import BoundingBox

    box = BoundingBox(np.array([-0.05, -0.05, 0.0]), np.array([0.05, 0.05, 0.1]))
    poses = [orbit_view((0, 0, 0.05), 20, a) for a in (10, 100, 190, 280)]
    candidates, centre, radius = candidates_from_poses(poses, box, PartitionConfig())
    assert [c.index for c in candidates] == [0, 1, 2, 3]
    assert [c.sector for c in candidates] == [0, 1, 2, 3]
    assert all(c.T_world_camera is p for c, p in zip(candidates, poses, strict=True))
    np.testing.assert_allclose(centre, [0, 0, 0.05], atol=1e-12)
    assert radius == pytest.approx(0.45)
    assert math.degrees(candidates[0].elevation) == pytest.approx(20)
    with pytest.raises(ValueError, match="none given"):
        candidates_from_poses([], box, PartitionConfig())


def test_given_views_take_their_sectors_about_the_point_they_look_at_not_about_a_shifted_box() -> None:
    from planner.candidates import candidates_from_poses, look_point
    from planner.config import PartitionConfig
    from planner.partitions import azimuth_of, sector_of
    from planner.types import BoundingBox, Pose

    # B grown along the first view (from azimuth 280) lies behind the object: its centre 0.16 m off the axis
    box = BoundingBox(np.array([-0.1, 0.0, 0.0]), np.array([0.1, 0.33, 0.1]))
    poses = [orbit_view((0, 0, 0.05), 10, a) for a in (280, 10, 100, 190)]
    looked_at = look_point(poses)
    assert looked_at is not None
    np.testing.assert_allclose(looked_at, [0, 0, 0.05], atol=1e-9)
    candidates, centre, radius = candidates_from_poses(poses, box, PartitionConfig())
    np.testing.assert_allclose(centre, [0, 0, 0.05], atol=1e-9)
    assert [c.sector for c in candidates] == [3, 0, 1, 2]  # a quarter turn apart: four sectors
    assert radius == pytest.approx(0.45)
    # about the box's centre the view a quarter turn on (azimuth 10) would fall into the first view's sector
    about_box = [sector_of(azimuth_of(p.translation, box.center), PartitionConfig()) for p in poses]
    assert about_box[:2] == [3, 3]
    # parallel axes meet nowhere: the box's centre is used
    parallel = [Pose(np.eye(3), np.array([x, 0.0, 0.0])) for x in (0.0, 0.1, 0.2)]
    assert look_point(parallel) is None
    _, centre, _ = candidates_from_poses(parallel, box, PartitionConfig())
    np.testing.assert_allclose(centre, box.center)


def test_a_recorded_cell_times_its_moves_with_the_cells_arm_and_leaves_untimed_the_views_no_arm_takes() -> None:
    from types import SimpleNamespace

    from devices.recorded import STRAIGHT_SPEED, RecordedSet, RecordedView, planner_config_for_set, sees_from_below

    target = (0.0, 0.0, 0.08)
    poses = [orbit_view(target, 30, 10), orbit_view(target, 35, 80), orbit_view(target, -50, 200)]
    points = np.array([[0.0, 0.0, 0.45], [0.01, 0.0, 0.45], [0.0, 0.01, 0.45]])
    recorded = RecordedSet("three", tuple(RecordedView(f"v{i}", points, p) for i, p in enumerate(poses)), SMALL)
    cell = RecordedCell(recorded)  # the default cell: the UR5
    assert cell.timing is not None
    first = cell.move_to(poses[0])
    second = cell.move_to(poses[1])
    assert first.timed and second.timed and second.trajectory is not None
    assert 0.2 < second.duration < 20  # the UR5's move between two views 70 degrees apart on the plate
    assert np.allclose(cell.pose.matrix, poses[1].matrix, atol=1e-12)  # the camera is at the recorded view
    state = cell.device_state()
    below = cell.move_to(poses[2])  # under the plate top: no arm of the cell takes it, the data is still there
    assert not below.timed and below.q is None
    assert np.allclose(cell.capture().T_world_camera.matrix, poses[2].matrix)
    cands = [SimpleNamespace(T_world_camera=p) for p in poses]
    times = cell.move_times(cands, [0, 1, 2])
    # between arm views the arm's own estimate, to and from the view under the plate the straight travel
    d = np.linalg.norm(poses[0].translation - poses[2].translation)
    assert times[1, 3] == pytest.approx(d / STRAIGHT_SPEED) and times[3, 1] == pytest.approx(d / STRAIGHT_SPEED)
    assert np.isfinite(times[1, 2]) and times[1, 2] != pytest.approx(
        np.linalg.norm(poses[0].translation - poses[1].translation) / STRAIGHT_SPEED
    )
    # a resume puts the timing arm back where it stood: the same move is planned again
    other = RecordedCell(recorded)
    other.restore_device_state(state)
    assert other.timing is not None and cell.timing is not None
    np.testing.assert_allclose(other.timing.arm.joint_positions(), cell.timing.arm.joint_positions())
    # without a URDF arm nothing is timed
    sphere = RecordedCell(recorded, CellConfig(kinematics="reach_sphere"))
    assert sphere.timing is None and not sphere.move_to(poses[1]).timed
    # a view from under the plate top: the planner's voxel floor goes
    assert sees_from_below(recorded) and not planner_config_for_set(PlannerConfig(), recorded).voxel.floor
    above = RecordedSet("two", recorded.views[:2], SMALL)
    assert not sees_from_below(above) and planner_config_for_set(PlannerConfig(), above).voxel.floor
