"""Value types: validation messages name the bad field; geometry is right."""

import numpy as np
import pytest

from planner.types import BoundingBox, DepthFrame, Ellipsoid, Intrinsics, Pose, unit_quaternion


def rot_z(a: float) -> np.ndarray:
    c, s = np.cos(a), np.sin(a)
    return np.array([[c, -s, 0], [s, c, 0], [0, 0, 1.0]])


def test_pose_compose_inverse_and_apply() -> None:
    T_a_b = Pose(rot_z(np.pi / 2), [1.0, 0.0, 0.0])
    assert np.allclose(T_a_b.apply([[1.0, 0.0, 0.0]]), [[1.0, 1.0, 0.0]])
    assert np.allclose((T_a_b @ T_a_b.inverse()).matrix, np.eye(4))
    T_b_c = Pose(np.eye(3), [0.0, 2.0, 0.0])
    assert np.allclose((T_a_b @ T_b_c).translation, [-1.0, 0.0, 0.0])


def test_pose_quaternion_round_trip() -> None:
    rng = np.random.default_rng(1)
    for _ in range(20):
        q = rng.normal(size=4)
        q /= np.linalg.norm(q)
        pose = Pose.from_wxyz(q, [0.1, 0.2, 0.3])
        back = Pose.from_wxyz(pose.wxyz, pose.translation)
        assert np.allclose(back.rotation, pose.rotation, atol=1e-9)
        assert np.isclose(abs(np.dot(pose.wxyz, q)), 1.0)
    assert Pose.from_dict(Pose.identity().to_dict()).wxyz.tolist() == [1.0, 0.0, 0.0, 0.0]


def test_look_at_is_opencv() -> None:
    T_world_camera = Pose.look_at([0.5, 0.0, 0.3], [0.0, 0.0, 0.0])
    z = T_world_camera.rotation[:, 2]
    assert np.allclose(z, -np.array([0.5, 0.0, 0.3]) / np.linalg.norm([0.5, 0.0, 0.3]))
    # image +y (down) has a negative world-z component; the target projects to the centre
    assert T_world_camera.rotation[2, 1] < 0
    p_c = T_world_camera.inverse().apply([[0.0, 0.0, 0.0]])[0]
    assert np.allclose(p_c[:2], 0.0) and p_c[2] > 0


def test_pose_rejects_bad_rotation() -> None:
    with pytest.raises(ValueError, match="rotation"):
        Pose(np.diag([1.0, 1.0, -1.0]), [0, 0, 0])
    with pytest.raises(ValueError, match="translation: 1 non-finite"):
        Pose(np.eye(3), [0, np.nan, 0])
    with pytest.raises(ValueError, match=r"translation: expected shape \(3\)"):
        Pose(np.eye(3), [0, 0])


def test_depth_frame_back_projection_and_validation() -> None:
    k = Intrinsics(width=4, height=3, fx=2.0, fy=2.0, cx=1.5, cy=1.0)
    depth = np.zeros((3, 4), np.float32)
    depth[1, 3] = 2.0
    frame = DepthFrame(depth, Pose(np.eye(3), [0, 0, 1.0]), k)
    assert np.allclose(frame.points_camera, [[(3 - 1.5) * 2.0 / 2.0, 0.0, 2.0]])
    assert np.allclose(frame.points_world, [[1.5, 0.0, 3.0]])
    bad = depth.copy()
    bad[0, 0] = np.nan
    with pytest.raises(ValueError, match="depth: 1 non-finite"):
        DepthFrame(bad, Pose.identity(), k)
    with pytest.raises(ValueError, match=r"depth: expected shape \(3, 4\)"):
        DepthFrame(np.zeros((4, 3), np.float32), Pose.identity(), k)
    with pytest.raises(ValueError, match="negative"):
        DepthFrame(-depth, Pose.identity(), k)


def test_depth_frame_from_points_round_trip() -> None:
    k = Intrinsics(width=64, height=48, fx=60.0, fy=60.0, cx=31.5, cy=23.5)
    T = Pose.look_at([0.0, -0.5, 0.2], [0.0, 0.0, 0.1])
    depth = np.full((48, 64), 0.5, np.float32)
    frame = DepthFrame(depth, T, k)
    again = DepthFrame.from_points(frame.points_world, T, k)
    assert np.allclose(again.depth, depth, atol=1e-5)


def test_ellipsoid_quadric_and_dual() -> None:
    R = rot_z(0.3)
    e = Ellipsoid([0.1, -0.2, 0.3], [0.05, 0.1, 0.2], R, "frontier")
    Q = e.as_quadric()
    surface = e.center + R @ np.array([0.05, 0.0, 0.0])
    X = np.append(surface, 1.0)
    assert abs(X @ Q @ X) < 1e-12
    assert np.append(e.center, 1.0) @ Q @ np.append(e.center, 1.0) < 0
    Qinv = np.linalg.inv(Q)
    assert np.allclose(Qinv / Qinv[3, 3], e.dual() / e.dual()[3, 3])
    assert e.contains([surface * 0.999 + e.center * 0.001]).all()
    assert np.isclose(e.volume, 4 / 3 * np.pi * 0.05 * 0.1 * 0.2)
    with pytest.raises(ValueError, match="axes"):
        Ellipsoid([0, 0, 0], [0.1, 0.0, 0.1], np.eye(3), "occupied")
    with pytest.raises(ValueError, match="kind"):
        Ellipsoid([0, 0, 0], [0.1, 0.1, 0.1], np.eye(3), "empty")  # type: ignore[arg-type]


def test_bounding_box() -> None:
    box = BoundingBox([0, 0, 0], [0.3, 0.4, 0.0])
    assert np.isclose(box.diagonal, 0.5)
    assert box.contains([[0.1, 0.1, 0.0], [0.1, 0.5, 0.0]]).tolist() == [True, False]
    with pytest.raises(ValueError, match="upper"):
        BoundingBox([0, 0, 0], [-1, 0, 0])


@pytest.mark.parametrize(
    ("wxyz", "unit"),
    [
        ([1e200] * 4, [0.5] * 4),
        ([1e308, 1e308, 0.0, 0.0], [2**-0.5, 2**-0.5, 0.0, 0.0]),
        ([0.0, 0.0, 0.0, -3.0], [0.0, 0.0, 0.0, -1.0]),
    ],
)
def test_a_quaternion_is_normalised_without_overflow(wxyz: list[float], unit: list[float]) -> None:
    assert np.allclose(unit_quaternion(np.array(wxyz)), unit)
    pose = Pose.from_wxyz(wxyz, [0.0, 0.0, 0.0])
    assert np.allclose(pose.rotation, Pose.from_wxyz(unit, [0.0, 0.0, 0.0]).rotation)
    assert not np.allclose(pose.rotation, np.eye(3))


def test_a_zero_or_non_finite_quaternion_is_refused() -> None:
    for bad in ([0.0] * 4, [1e-12, 0.0, 0.0, 0.0], [np.inf, 0.0, 0.0, 0.0], [np.nan, 1.0, 0.0, 0.0]):
        with pytest.raises(ValueError, match="wxyz"):
            Pose.from_wxyz(bad, [0.0, 0.0, 0.0])
