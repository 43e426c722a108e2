"""Cell: table/base frames, turntable angle choice, reachability numbers, move_to, capture, pose noise."""

from __future__ import annotations

import math

import numpy as np
import pytest

from devices.angles import wrap_angle
from devices.builtins import make_builtin
from devices.cell import Cell, Motion, rz
from devices.config import CameraConfig, CellConfig
from devices.protocols import DeviceError, UnreachableError
from devices.sim import SimulatedArm, SimulatedTurntable, make_sim_cell
from planner.types import DepthFrame, Intrinsics, Pose

SPHERE = CellConfig(kinematics="reach_sphere")
"""These tests pin the reach-sphere cell (the URDF arm's are in test_arm_cell.py)."""


def _angle_between(a: Pose, b: Pose) -> float:
    R = a.rotation.T @ b.rotation
    return math.degrees(math.acos(np.clip((np.trace(R) - 1) / 2, -1, 1)))


@pytest.fixture(scope="module")
def l_block():
    return make_builtin("l-block")


def test_rz_and_wrap() -> None:
    np.testing.assert_allclose(rz(math.pi / 2).apply([[1.0, 0.0, 0.3]]), [[0.0, 1.0, 0.3]], atol=1e-15)
    assert wrap_angle(3 * math.pi) == pytest.approx(math.pi)
    assert wrap_angle(-math.pi) == pytest.approx(math.pi)
    assert wrap_angle(-0.5 + 2 * math.pi) == pytest.approx(-0.5)


def test_plan_motion_turns_the_camera_to_the_arm() -> None:
    cell = make_sim_cell(None, cell_config=SPHERE)
    view = Pose.look_at((0.0, 0.3, 0.2), (0.0, 0.0, 0.1))  # azimuth +90 degrees in the table frame
    motion = cell.plan_motion(view)
    assert isinstance(motion, Motion)
    assert motion.angle == pytest.approx(math.pi / 2)  # arm azimuth (180) - camera azimuth (90)
    np.testing.assert_allclose(motion.T_base_camera.translation, [-0.3, 0.0, 0.2], atol=1e-12)
    np.testing.assert_allclose(motion.T_base_camera.matrix, (rz(math.pi / 2) @ view).matrix, atol=1e-12)
    # a camera at azimuth -135 degrees: theta = 180 - (-135) = 315 = -45 degrees
    motion = cell.plan_motion(Pose.look_at((-0.2, -0.2, 0.3), (0.0, 0.0, 0.1)))
    assert motion.angle == pytest.approx(-math.pi / 4)
    np.testing.assert_allclose(motion.T_base_camera.translation, [-0.2 * math.sqrt(2), 0.0, 0.3], atol=1e-12)


def test_camera_on_the_axis_keeps_the_turntable_angle() -> None:
    cell = make_sim_cell(None, cell_config=SPHERE)
    cell.turntable.rotate_to(0.7)
    top = Pose(np.diag([1.0, -1.0, -1.0]), np.array([0.0, 0.0, 0.5]))
    motion = cell.plan_motion(top)
    assert motion.angle == pytest.approx(0.7)
    # reach from the base (-0.45, 0, 0) to (0, 0, 0.5): sqrt(0.45^2 + 0.5^2) = 0.6727
    assert cell.is_reachable(top)


@pytest.mark.parametrize(
    ("position", "pattern"),
    [
        ((0.0, 0.0, 0.9), r"camera 1\.006 m from the arm base, beyond arm_reach 0\.800 m"),
        ((0.3, 0.0, 0.9), r"camera 0\.912 m from the arm base, beyond arm_reach"),
        ((-0.4, 0.0, 0.05), r"camera 0\.071 m from the arm base, nearer than arm_min_reach 0\.150 m"),
        ((0.2, 0.1, 0.005), r"camera at height 0\.005 m is below the plate top \+ clearance \(0\.010 m\)"),
        ((0.2, 0.1, -0.3), r"camera at height -0\.300 m is below"),
    ],
)
def test_unreachable_views_say_why(position: tuple[float, float, float], pattern: str) -> None:
    cell = make_sim_cell(None, cell_config=SPHERE)
    view = Pose(np.eye(3), np.array(position))
    with pytest.raises(UnreachableError, match=pattern):
        cell.plan_motion(view)
    assert not cell.is_reachable(view)


def test_reach_boundary_numbers() -> None:
    cell = make_sim_cell(None, cell_config=SPHERE)
    # After turning, a camera at horizontal radius rho and height z is sqrt((0.45 - rho)^2 + z^2) from the base.
    assert cell.is_reachable(Pose(np.eye(3), np.array([0.0, 0.5, 0.79])))  # sqrt(0.05^2 + 0.79^2) = 0.7916
    assert not cell.is_reachable(Pose(np.eye(3), np.array([0.0, 0.5, 0.81])))  # 0.8116
    assert cell.is_reachable(Pose(np.eye(3), np.array([0.35, 0.0, 0.12])))  # sqrt(0.1^2 + 0.12^2) = 0.156
    assert not cell.is_reachable(Pose(np.eye(3), np.array([0.35, 0.0, 0.1])))  # 0.1414
    custom = make_sim_cell(
        None, cell_config=CellConfig(kinematics="reach_sphere", arm_base=(0.0, -0.5, 0.0), arm_reach=0.6)
    )
    motion = custom.plan_motion(Pose(np.eye(3), np.array([0.3, 0.0, 0.2])))
    assert motion.angle == pytest.approx(-math.pi / 2)  # the arm sits at azimuth -90 degrees
    np.testing.assert_allclose(motion.T_base_camera.translation, [0.0, -0.3, 0.2], atol=1e-12)


def test_move_to_moves_nothing_when_unreachable() -> None:
    cell = make_sim_cell(None, cell_config=SPHERE)
    angle, pose = cell.turntable.angle, cell.arm.pose
    with pytest.raises(UnreachableError):
        cell.move_to(Pose(np.eye(3), np.array([0.0, 0.0, 2.0])))
    assert cell.turntable.angle == angle and cell.arm.pose is pose
    assert isinstance(cell.turntable, SimulatedTurntable) and cell.turntable.rotations == 0
    assert isinstance(cell.arm, SimulatedArm) and cell.arm.moves == 0


def test_move_to_then_capture_reports_the_table_pose(l_block) -> None:
    cell = make_sim_cell(l_block, cell_config=SPHERE)
    view = Pose.look_at((0.25, 0.3, 0.35), (0.0, 0.0, 0.08))
    motion = cell.move_to(view)
    assert cell.turntable.angle == pytest.approx(motion.angle)
    np.testing.assert_allclose(cell.arm.pose.matrix, motion.T_base_camera.matrix, atol=1e-12)
    np.testing.assert_allclose(cell.pose.matrix, view.matrix, atol=1e-12)
    frame = cell.capture()
    np.testing.assert_allclose(frame.T_world_camera.matrix, view.matrix, atol=1e-12)
    assert frame.intrinsics == cell.intrinsics


def test_same_table_pose_at_two_turntable_angles_gives_the_same_image(l_block) -> None:
    cell = make_sim_cell(l_block, cell_config=SPHERE)
    view = Pose.look_at((0.25, -0.3, 0.3), (0.0, 0.0, 0.08))
    cell.move_to(view)
    first = cell.capture()
    # Reach the same table-frame pose the other way round: turn the plate by 2 rad and move the arm along.
    theta = cell.turntable.angle + 2.0
    cell.turntable.rotate_to(theta)
    cell.arm.move_to(rz(theta) @ view)
    second = cell.capture()
    np.testing.assert_allclose(second.T_world_camera.matrix, view.matrix, atol=1e-12)
    assert np.count_nonzero(first.depth) > 20_000
    np.testing.assert_allclose(second.depth, first.depth, atol=1e-5)


def test_turning_the_plate_under_a_fixed_arm_turns_the_object(l_block) -> None:
    cell = make_sim_cell(l_block, cell_config=SPHERE)
    before = cell.capture()
    cell.turntable.rotate_to(cell.turntable.angle + math.pi / 2)
    after = cell.capture()
    # The reported pose is the camera seen from the plate: rotated by -90 degrees about z.
    np.testing.assert_allclose(
        after.T_world_camera.matrix, (rz(-math.pi / 2) @ before.T_world_camera).matrix, atol=1e-12
    )
    assert np.mean(np.abs(after.depth - before.depth) > 1e-3) > 0.02  # the L looks different from the side


def test_initial_pose_and_the_starting_state(l_block) -> None:
    cell = make_sim_cell(l_block, cell_config=SPHERE)
    pose = cell.initial_pose()
    # elevation 30, azimuth 180, distance 0.55 about (0, 0, 0.1)
    np.testing.assert_allclose(pose.translation, [-0.55 * math.cos(math.pi / 6), 0.0, 0.1 + 0.275], atol=1e-12)
    forward = pose.rotation[:, 2]
    np.testing.assert_allclose(forward, ([0.0, 0.0, 0.1] - pose.translation) / 0.55, atol=1e-12)
    assert pose.rotation[2, 1] < 0  # image +y (down) points down in the world
    assert cell.is_reachable(pose)
    np.testing.assert_allclose(cell.pose.matrix, pose.matrix, atol=1e-12)  # make_sim_cell starts there
    assert cell.turntable.angle == pytest.approx(0.0)


def test_pose_noise_is_seeded_and_has_the_configured_size(l_block) -> None:
    camera = CameraConfig(width=64, height=48, fx=61.0, fy=61.0, cx=31.5, cy=23.5)
    noisy = CameraConfig(**{**camera.__dict__, "pose_noise_translation": 0.005, "pose_noise_rotation_deg": 1.0})
    a, b = make_sim_cell(l_block, noisy, SPHERE, seed=7), make_sim_cell(l_block, noisy, SPHERE, seed=7)
    true = a.pose
    frames = [a.capture() for _ in range(200)]
    np.testing.assert_array_equal(frames[0].T_world_camera.matrix, b.capture().T_world_camera.matrix)
    dt = np.array([f.T_world_camera.translation - true.translation for f in frames])
    assert dt.std() == pytest.approx(0.005, rel=0.1)
    angles = np.array([_angle_between(f.T_world_camera, true) for f in frames])
    # |rotation vector| of a 3-D Gaussian with sigma = 1 degree: mean sigma * sqrt(8 / pi) = 1.596
    assert angles.mean() == pytest.approx(1.596, rel=0.1)
    # the image is rendered from the true pose: identical to a noise-free cell's
    clean = make_sim_cell(l_block, camera, SPHERE, seed=7)
    np.testing.assert_array_equal(frames[0].depth, clean.capture().depth)


def test_cell_with_fake_devices_uses_only_the_protocols() -> None:
    class FakeCamera:
        intrinsics = Intrinsics(4, 3, 3.0, 3.0, 1.5, 1.0)

        def capture(self) -> DepthFrame:
            return DepthFrame(np.full((3, 4), 0.5, dtype=np.float32), Pose.identity(), self.intrinsics)

    class FakeArm:
        def __init__(self) -> None:
            self.pose = Pose.identity()

        def move_to(self, T_base_camera: Pose) -> None:
            if T_base_camera.translation[2] > 0.6:
                raise UnreachableError("driver: joint limit")
            self.pose = T_base_camera

    class FakeTable:
        angle = 0.0

        def rotate_to(self, angle: float) -> None:
            self.angle = angle

    cell = Cell(FakeCamera(), FakeArm(), FakeTable(), CellConfig(kinematics="reach_sphere", arm_reach=2.0))  # type: ignore[arg-type]
    view = Pose.look_at((0.3, 0.0, 0.3), (0.0, 0.0, 0.1))
    cell.move_to(view)
    frame = cell.capture()
    np.testing.assert_allclose(frame.T_world_camera.matrix, view.matrix, atol=1e-12)  # the cell sets the pose
    assert cell.turntable.angle == pytest.approx(math.pi)
    with pytest.raises(DeviceError, match="joint limit"):
        cell.move_to(Pose.look_at((0.3, 0.0, 0.7), (0.0, 0.0, 0.1)))


def test_bad_arguments() -> None:
    cell = make_sim_cell(None, cell_config=SPHERE)
    with pytest.raises(ValueError, match="T_table_camera: expected a Pose"):
        cell.plan_motion((0.0, 0.0, 0.5))  # type: ignore[arg-type]
    with pytest.raises(ValueError, match="pose_noise_translation: must be >= 0"):
        Cell(cell.camera, cell.arm, cell.turntable, pose_noise_translation=-1.0)


def test_is_reachable_closed_form_agrees_with_plan_motion() -> None:
    cell = make_sim_cell(None, CameraConfig(), SPHERE, seed=0)
    rng = np.random.default_rng(3)
    agree = 0
    for _ in range(300):
        eye = rng.uniform([-1.2, -1.2, -0.1], [1.2, 1.2, 1.2])
        pose = Pose.look_at(eye, [0.0, 0.0, 0.1])
        try:
            cell.plan_motion(pose)
            expected = True
        except UnreachableError:
            expected = False
        assert cell.is_reachable(pose) == expected
        agree += expected
    assert 20 < agree < 280  # both outcomes were exercised
