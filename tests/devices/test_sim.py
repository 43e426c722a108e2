"""SimulatedCamera / Arm / Turntable: analytic depths, the plate, range cut, noise, faults, protocols."""

from __future__ import annotations

import numpy as np
import open3d as o3d
import pytest
import trimesh

from devices.builtins import make_builtin
from devices.config import CameraConfig
from devices.protocols import Arm, Camera, CaptureError, DeviceError, Turntable
from devices.sim import SimulatedArm, SimulatedCamera, SimulatedTurntable, plate_mesh
from planner.types import Pose

DOWN = Pose(np.diag([1.0, -1.0, -1.0]), np.zeros(3))  # camera axes: +z forward = world -z


def _pose_down(height: float) -> Pose:
    return Pose(DOWN.rotation, np.array([0.0, 0.0, height]))


def _distance_to(mesh: trimesh.Trimesh, points: np.ndarray) -> np.ndarray:
    scene = o3d.t.geometry.RaycastingScene()
    scene.add_triangles(
        o3d.core.Tensor.from_numpy(np.ascontiguousarray(mesh.vertices, dtype=np.float32)),
        o3d.core.Tensor.from_numpy(np.ascontiguousarray(mesh.faces, dtype=np.uint32)),
    )
    return scene.compute_distance(o3d.core.Tensor.from_numpy(np.ascontiguousarray(points, dtype=np.float32))).numpy()


def test_plate_seen_from_above_is_at_the_analytic_depth() -> None:
    cam = SimulatedCamera(None, plate_radius=0.2, plate_thickness=0.02)
    depth = cam.render(_pose_down(0.5))
    assert depth.shape == (480, 480 * 4 // 3) and depth.dtype == np.float32
    valid = depth > 0
    np.testing.assert_allclose(depth[valid], 0.5, atol=1e-6)
    # the plate (radius 0.2 at 0.5 m, f = 610) covers a disc of radius 244 px about the principal point
    v, u = np.nonzero(valid)
    r = np.hypot(u - 319.5, v - 239.5)
    assert r.max() == pytest.approx(244.0, abs=1.5)
    assert np.count_nonzero(valid) == pytest.approx(np.pi * 244.0**2, rel=0.02)


def test_tilted_view_of_a_plane_matches_planar_z_depth() -> None:
    # A camera 0.4 m above the plate, tilted 30 degrees: every pixel's depth is planar z-depth.
    cam = SimulatedCamera(None, plate_radius=1.0, plate_thickness=0.02, config=CameraConfig(max_depth=5.0))
    pose = Pose.look_at((-0.4 / np.tan(np.radians(60)), 0.0, 0.4), (0.0, 0.0, 0.0))
    depth = cam.render(pose)
    k = cam.intrinsics
    v, u = np.mgrid[0 : k.height, 0 : k.width]
    rays_world = np.stack([(u - k.cx) / k.fx, (v - k.cy) / k.fy, np.ones(u.shape)], -1) @ pose.rotation.T
    t = -pose.translation[2] / rays_world[..., 2]  # ray parameter where z = 0; with camera z = 1 it is z-depth
    hit = pose.translation + t[..., None] * rays_world
    inside = (t > 0) & (np.hypot(hit[..., 0], hit[..., 1]) < 0.99)
    assert inside.sum() > 100_000
    np.testing.assert_allclose(depth[inside], t[inside], atol=1e-3)
    # centre pixel: the ray along the optical axis hits the plate centre at distance 0.4 / sin(60)
    assert depth[240, 320] == pytest.approx(0.4 / np.sin(np.radians(60)), abs=1e-3)


def test_box_face_at_known_distance_and_points_on_the_surface() -> None:
    box = make_builtin("box")  # 0.2 x 0.14 x 0.1, its -x face at x = -0.1
    cam = SimulatedCamera(box, plate_radius=0.2)
    pose = Pose.look_at((-0.5, 0.0, 0.05), (0.0, 0.0, 0.05))
    depth = cam.render(pose)
    assert depth[239, 319] == pytest.approx(0.4, abs=1e-6)
    # the face spans y in [-0.07, 0.07]: at 0.4 m, 610 px/m * 0.07 / 0.4 = 106.75 px either side
    row = depth[239]
    face = np.nonzero(np.isclose(row, 0.4, atol=1e-6))[0]
    assert face.min() == pytest.approx(319.5 - 106.75, abs=1.0) and face.max() == pytest.approx(319.5 + 106.75, abs=1.0)
    cam.pose_source = lambda: pose
    frame = cam.capture()
    pts = frame.points_world
    on_object = pts[pts[:, 2] > 1e-4]
    assert len(on_object) > 10_000
    assert _distance_to(box, on_object).max() < 1e-3
    plate_pts = pts[pts[:, 2] <= 1e-4]  # the plate's top and its rim
    assert len(plate_pts) > 1_000
    assert _distance_to(plate_mesh(0.2, 0.02), plate_pts).max() < 1e-3


def test_points_land_on_a_curved_mesh() -> None:
    mug = make_builtin("mug")
    cam = SimulatedCamera(mug, pose_source=lambda: Pose.look_at((0.3, -0.35, 0.3), (0.0, 0.0, 0.08)))
    pts = cam.capture().points_world
    on_object = pts[pts[:, 2] > 1e-4]
    assert len(on_object) > 5_000
    assert _distance_to(mug, on_object).max() < 1e-3


def test_the_plate_hides_the_underside() -> None:
    sphere = make_builtin("sphere")  # touches the plate top at the origin
    below = Pose(np.eye(3), np.array([0.0, 0.0, -0.3]))  # camera +z = world +z: looking straight up
    with_plate = SimulatedCamera(sphere, plate_radius=0.2, plate_thickness=0.02).render(below)
    without = SimulatedCamera(sphere, plate_radius=0.0).render(below)
    assert with_plate[239, 319] == pytest.approx(0.28, abs=1e-6)  # the plate's bottom face at z = -0.02
    assert without[239, 319] == pytest.approx(0.3, abs=1e-4)  # the sphere's lowest point
    assert np.all(with_plate[239, 200:440] == pytest.approx(0.28, abs=1e-6))


def test_depth_range_cut() -> None:
    pose = _pose_down(0.5)
    assert not np.any(SimulatedCamera(None, CameraConfig(max_depth=0.45)).render(pose))
    assert not np.any(SimulatedCamera(None, CameraConfig(min_depth=0.55, max_depth=2.0)).render(pose))
    assert np.count_nonzero(SimulatedCamera(None, CameraConfig(min_depth=0.45, max_depth=0.55)).render(pose)) > 100_000
    assert not np.any(SimulatedCamera(None).render(_pose_down(-0.5)))  # looking down from below: nothing


def test_depth_noise_is_gaussian_and_seeded() -> None:
    pose = _pose_down(0.5)

    def capture(seed: int) -> np.ndarray:
        cam = SimulatedCamera(None, CameraConfig(depth_noise_std=0.002), pose_source=lambda: pose, seed=seed)
        return cam.capture().depth

    a, b, c = capture(1), capture(1), capture(2)
    np.testing.assert_array_equal(a, b)
    assert not np.array_equal(a, c)
    values = a[a > 0].astype(np.float64)
    assert values.mean() == pytest.approx(0.5, abs=1e-4)
    assert values.std() == pytest.approx(0.002, rel=0.02)


def test_capture_needs_a_pose_and_reports_it() -> None:
    cam = SimulatedCamera(None)
    with pytest.raises(CaptureError, match="no pose source"):
        cam.capture()
    pose = _pose_down(0.4)
    cam.pose_source = lambda: pose
    frame = cam.capture()
    np.testing.assert_array_equal(frame.T_world_camera.matrix, pose.matrix)
    assert frame.intrinsics == cam.intrinsics == CameraConfig().intrinsics
    assert cam.captures == 1


def test_fault_injection_fires_once_and_changes_nothing() -> None:
    cam = SimulatedCamera(None, pose_source=lambda: _pose_down(0.5))
    cam.fail_next = CaptureError("lens cap on")
    with pytest.raises(CaptureError, match="lens cap on"):
        cam.capture()
    assert cam.captures == 0 and cam.fail_next is None
    cam.capture()

    arm = SimulatedArm()
    arm.fail_next = DeviceError("estop")
    with pytest.raises(DeviceError, match="estop"):
        arm.move_to(_pose_down(0.5))
    assert np.allclose(arm.pose.matrix, np.eye(4)) and arm.moves == 0
    arm.move_to(_pose_down(0.5))
    assert arm.pose.translation[2] == 0.5 and arm.moves == 1

    table = SimulatedTurntable()
    table.fail_next = DeviceError("jammed")
    with pytest.raises(DeviceError, match="jammed"):
        table.rotate_to(1.0)
    assert table.angle == 0.0 and table.rotations == 0


def test_turntable_wraps_and_validates() -> None:
    table = SimulatedTurntable()
    table.rotate_to(3 * np.pi)
    assert table.angle == pytest.approx(np.pi)
    table.rotate_to(-np.pi / 2 + 4 * np.pi)
    assert table.angle == pytest.approx(-np.pi / 2)
    with pytest.raises(ValueError, match="angle: must be a finite number"):
        table.rotate_to(float("nan"))
    with pytest.raises(ValueError, match="T_base_camera: expected a Pose"):
        SimulatedArm().move_to("home")  # type: ignore[arg-type]


def test_simulated_devices_satisfy_the_protocols() -> None:
    assert isinstance(SimulatedCamera(None), Camera)
    assert isinstance(SimulatedArm(), Arm)
    assert isinstance(SimulatedTurntable(), Turntable)


def test_plate_mesh_geometry() -> None:
    plate = plate_mesh(0.2, 0.02)
    np.testing.assert_allclose(plate.bounds, [[-0.2, -0.2, -0.02], [0.2, 0.2, 0.0]], atol=1e-12)
