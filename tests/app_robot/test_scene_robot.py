"""The arm drawn into a real viser server: nodes, ghost, camera path, animation."""

from __future__ import annotations

import threading
from collections.abc import Iterator

import numpy as np
import pytest

from app.scene.robot import RobotScene, ghost_pose
from devices.arm.config import ArmConfig
from devices.arm.kinematics import ArmKinematics
from devices.arm.motion import time_path
from devices.arm.reach import rz_matrix


@pytest.fixture(scope="module")
def kin() -> ArmKinematics:
    return ArmKinematics(ArmConfig(), plate_radius=0.2, plate_thickness=0.02)


@pytest.fixture(scope="module")
def server() -> Iterator[object]:
    import viser

    s = viser.ViserServer(host="127.0.0.1", port=0)
    yield s
    s.stop()


@pytest.fixture(scope="module")
def robot(server, kin: ArmKinematics) -> RobotScene:
    return RobotScene(server, kin.model)


def names(server) -> set[str]:
    return set(server.scene._handle_from_node_name)


def test_the_arm_is_drawn_from_its_meshes(server, robot: RobotScene, kin: ArmKinematics) -> None:
    nodes = names(server)
    assert "/robot/arm" in nodes and "/robot/ghost" in nodes
    arm_meshes = [n for n in nodes if n.startswith("/robot/arm/") and "shoulder_link" in n]
    assert arm_meshes, sorted(nodes)[:20]
    robot.show(kin.home, 0.4)
    frame = server.scene.get_handle_by_name("/robot/arm")
    mount = rz_matrix(-0.4) @ kin.model.T_base_mount.translation  # the table frame: the arm turns with the plate
    np.testing.assert_allclose(frame.position, mount, atol=1e-6)
    np.testing.assert_allclose(robot.q, kin.home)
    with pytest.raises(ValueError, match=r"^q: expected \(6,\)"):
        robot.show(np.zeros(3), 0.0)


def test_ghost_and_camera_path(server, robot: RobotScene, kin: ArmKinematics) -> None:
    target = kin.home + np.array([0.6, 0.2, -0.3, 0.1, 0.0, 0.2])
    robot.show_ghost(target, 0.3)
    assert server.scene.get_handle_by_name("/robot/ghost").visible
    trajectory = time_path(kin.model, np.stack([kin.home, target]))
    points = robot.show_path(trajectory, 0.3)
    assert points is not None and "/robot/path" in names(server)
    end = ghost_pose(kin.model, target, 0.3)
    np.testing.assert_allclose(points[-1], end.translation, atol=1e-9)  # the path ends at the ghost's camera
    robot.show_path(None)
    robot.show_ghost(None)
    assert "/robot/path" not in names(server)
    assert not server.scene.get_handle_by_name("/robot/ghost").visible


def test_animation_plays_a_trajectory_to_its_end(robot: RobotScene, kin: ArmKinematics) -> None:
    target = kin.home + np.array([0.3, -0.1, 0.2, 0.0, 0.1, 0.0])
    trajectory = time_path(kin.model, np.stack([kin.home, target]))
    done = threading.Event()
    robot.animate(trajectory, 0.0, speed=20.0, on_done=done.set)
    assert done.wait(10.0)
    np.testing.assert_allclose(robot.q, target, atol=1e-9)
    with pytest.raises(ValueError, match=r"^speed"):
        robot.animate(trajectory, 0.0, speed=0.0)
