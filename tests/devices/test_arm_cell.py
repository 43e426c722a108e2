"""The cell with the UR5: moves are joint trajectories, the camera pose is forward kinematics, faults stop the arm
where it is."""

from __future__ import annotations

import math
import pickle
import threading
import time

import numpy as np
import pytest

from devices.arm.sim_arm import SimulatedJointArm
from devices.builtins import make_builtin
from devices.faults import FaultConfig, FaultInjector, with_faults
from devices.protocols import DeviceError, JointArm, UnreachableError
from devices.sim import make_sim_cell
from planner.types import BoundingBox, Pose
from tests.helpers import orbit_view

TARGET = np.array([0.0, 0.0, 0.08])


def view(elevation_deg: float, azimuth_deg: float, distance: float = 0.45) -> Pose:
    return orbit_view(TARGET, elevation_deg, azimuth_deg, distance)


def angle_deg(a: np.ndarray, b: np.ndarray) -> float:
    return math.degrees(math.acos(min(1.0, (np.trace(a.T @ b) - 1) / 2)))


@pytest.fixture(scope="module")
def l_block():
    return make_builtin("l-block", 0.2)


@pytest.fixture()
def cell(l_block):
    c = make_sim_cell(l_block)
    c.set_object_box(BoundingBox(np.array([-0.1, -0.1, 0.0]), np.array([0.1, 0.1, 0.2])))
    return c


def test_the_default_cell_has_the_ur5_and_starts_at_the_initial_view(cell) -> None:
    assert cell.kinematics is not None and isinstance(cell.arm, JointArm)
    assert cell.arm.joint_names[0] == "shoulder_pan_joint"
    q = cell.joint_positions()
    assert cell.kinematics.violations(q, cell.angle) is None
    start = cell.initial_pose()
    assert np.linalg.norm(cell.pose.translation - start.translation) < 1e-3
    assert angle_deg(cell.pose.rotation, start.rotation) < 0.1
    assert cell.arm.moves == 0 and cell.turntable.rotations == 0


def test_move_to_runs_a_trajectory_and_forward_kinematics_gives_the_view(cell) -> None:
    target = view(35, 60)
    before = cell.joint_positions()
    motion = cell.move_to(target)
    assert cell.arm.moves == 1
    assert motion.trajectory is not None and motion.q is not None
    np.testing.assert_allclose(motion.trajectory.start, before)
    np.testing.assert_allclose(cell.joint_positions(), motion.q)
    assert math.isclose(cell.angle, motion.angle)
    assert np.linalg.norm(cell.pose.translation - target.translation) < 1e-3
    assert angle_deg(cell.pose.rotation, target.rotation) < 0.1
    frame = cell.capture()  # the frame's pose is the forward kinematics, in the table frame
    np.testing.assert_allclose(frame.T_world_camera.matrix, cell.pose.matrix, atol=1e-12)
    assert motion.duration >= motion.trajectory.duration > 0
    assert motion.path_length == pytest.approx(motion.trajectory.path_length()) and motion.path_length > 0
    doc = motion.to_json()
    assert doc["joints"] == pytest.approx(list(motion.q)) and doc["move_duration"] == motion.duration
    for q in motion.trajectory.positions[:: max(1, len(motion.trajectory.positions) // 20)]:
        assert cell.kinematics.violations(q, motion.angle) is None


def test_an_unreachable_view_moves_nothing_and_says_why(cell) -> None:
    q, angle = cell.joint_positions(), cell.angle
    far = Pose.look_at([1.8, 0.4, 0.5], TARGET)
    assert cell.reachability(far) == (False, "no_ik") and not cell.is_reachable(far)
    with pytest.raises(UnreachableError, match="unreachable: no_ik") as info:
        cell.move_to(far)
    assert info.value.reason == "no_ik"
    np.testing.assert_array_equal(cell.joint_positions(), q)
    assert cell.angle == angle and cell.arm.moves == 0
    many = cell.reachability_many([view(30, 0), far])
    assert many[0] == (True, None) and many[1] == (False, "no_ik")


def test_unreachable_error_keeps_its_reason_across_processes() -> None:
    err = pickle.loads(pickle.dumps(UnreachableError("unreachable: collision:wrist_1_link:object", "collision:a:b")))
    assert err.reason == "collision:a:b" and str(err) == "unreachable: collision:wrist_1_link:object"


def test_move_estimates_rank_near_views_first(cell) -> None:
    here = cell.pose
    near = Pose(here.rotation, here.translation + np.array([0.0, 0.0, 0.02]))
    assert cell.move_estimate(here) < 0.5
    assert cell.move_estimate(near) < cell.move_estimate(view(60, 200))
    assert cell.move_estimate(Pose.look_at([2.0, 0.0, 0.3], TARGET)) == math.inf


def test_arm_halfway_stops_the_joint_arm_half_way_through_its_trajectory(l_block) -> None:
    injector = FaultInjector(FaultConfig.from_dict({"schedule": [{"kind": "arm_halfway", "at": 1}]}))
    cell = with_faults(make_sim_cell(l_block), injector)
    target = view(40, 100)
    motion = cell.plan_motion(target)
    with pytest.raises(DeviceError, match="halfway"):
        cell.move_to(target)
    assert math.isclose(cell.angle, motion.angle)  # the plate turned first
    assert motion.trajectory is not None
    np.testing.assert_allclose(cell.joint_positions(), motion.trajectory.sample(0.5 * motion.trajectory.duration))
    assert cell.kinematics.violations(cell.joint_positions(), cell.angle) is None
    cell.move_to(target)  # the retry plans from where the arm stopped and gets there
    assert np.linalg.norm(cell.pose.translation - target.translation) < 1e-3


def test_turntable_error_leaves_the_plate_and_the_joints(l_block) -> None:
    cell = with_faults(make_sim_cell(l_block), FaultInjector(FaultConfig(turntable_error=1.0)))
    q, angle = cell.joint_positions(), cell.angle
    with pytest.raises(DeviceError, match="turntable"):
        cell.move_to(view(40, 100))
    np.testing.assert_array_equal(cell.joint_positions(), q)
    assert cell.angle == angle


def test_real_time_execution_reports_progress_and_stops_where_it_is(cell) -> None:
    motion = cell.plan_motion(view(40, -100))
    assert motion.trajectory is not None and motion.trajectory.duration > 0.5
    seen: list[float] = []
    arm = SimulatedJointArm(cell.arm.joint_names, motion.trajectory.start, real_time=True, time_scale=0.2)
    arm.on_progress = lambda t, q: seen.append(t)
    arm.execute(motion.trajectory)
    np.testing.assert_allclose(arm.joint_positions(), motion.trajectory.end)
    assert seen == sorted(seen) and seen[-1] == pytest.approx(motion.trajectory.duration) and len(seen) > 5

    slow = SimulatedJointArm(cell.arm.joint_names, motion.trajectory.start, real_time=True, time_scale=4.0)
    threading.Timer(0.3, slow.stop).start()
    with pytest.raises(DeviceError, match="stopped after"):
        slow.execute(motion.trajectory)
    stopped = slow.joint_positions()
    assert not np.allclose(stopped, motion.trajectory.start) and not np.allclose(stopped, motion.trajectory.end)
    time.sleep(0.05)
    np.testing.assert_array_equal(slow.joint_positions(), stopped)  # it stays where it stopped


def test_the_joint_arm_refuses_a_trajectory_that_starts_elsewhere(cell) -> None:
    motion = cell.plan_motion(view(40, -100))
    assert motion.trajectory is not None
    arm = SimulatedJointArm(cell.arm.joint_names, motion.trajectory.start + 0.1)
    with pytest.raises(DeviceError, match=r"starts 0\.1000 rad away"):
        arm.execute(motion.trajectory)
    with pytest.raises(ValueError, match=r"^q: expected"):
        SimulatedJointArm(cell.arm.joint_names, np.zeros(3))


def test_device_state_brings_a_resumed_cell_to_the_same_joints(l_block) -> None:
    a, b = make_sim_cell(l_block), make_sim_cell(l_block)
    a.move_to(view(40, 100))
    state = a.device_state()
    assert len(state["arm"]["q"]) == 6 and state["arm"]["angle"] == a.angle
    b.restore_device_state(state)
    np.testing.assert_array_equal(b.joint_positions(), a.joint_positions())
    assert b.angle == a.angle and b.turntable.rotations == 0 and b.arm.moves == 0
    np.testing.assert_allclose(b.arm.pose.matrix, a.arm.pose.matrix)  # a joint arm's pose: its forward kinematics
    with pytest.raises(ValueError, match=r"^device state: cannot restore"):
        b.restore_device_state({"arm": {"q": [0.0, 1.0], "angle": 0.0}})
    np.testing.assert_array_equal(b.joint_positions(), a.joint_positions())  # nothing half-restored


def test_a_new_cell_starts_where_its_own_config_says_and_the_kept_move_is_the_one_it_plans(l_block) -> None:
    """make_sim_cell keeps the initial move per cell config (every session's create asks it): a cell built from
    the kept answer stands where one planned afresh stands, and another initial view gets its own move."""
    from devices import sim
    from devices.config import CellConfig

    other = CellConfig(initial_azimuth_deg=90.0, initial_elevation_deg=45.0)
    kept = make_sim_cell(l_block), make_sim_cell(l_block, cell_config=other)  # the answers are kept by now
    sim._INITIAL_MOVES.clear()
    fresh = make_sim_cell(l_block), make_sim_cell(l_block, cell_config=other)  # planned again
    assert len(sim._INITIAL_MOVES) == 2
    for a, b in zip(kept, fresh, strict=True):
        np.testing.assert_array_equal(a.joint_positions(), b.joint_positions())
        assert a.angle == b.angle and a.arm.moves == 0 and a.turntable.rotations == 0
        start = a.initial_pose()
        assert np.linalg.norm(a.pose.translation - start.translation) < 1e-3
    assert np.linalg.norm(kept[0].pose.translation - kept[1].pose.translation) > 0.1
    kept[0].move_to(view(40, 100))  # a cell's own moves leave the kept answer alone
    np.testing.assert_array_equal(make_sim_cell(l_block).joint_positions(), fresh[0].joint_positions())


def test_move_to_runs_a_prepared_motion_and_plans_again_one_the_arm_moved_away_from(cell, monkeypatch) -> None:
    """The motion handed to ``move_to`` is run as it was planned (no second plan); one planned before the arm moved
    elsewhere starts where the arm no longer is, so the cell plans the move again."""
    a, b = view(35, 60), view(40, -30)
    prepared_a, prepared_b = cell.plan_motion(a), cell.plan_motion(b)  # both from the initial configuration
    plans: list[Pose] = []
    plan = cell.kinematics.plan

    def counted(T_table_camera: Pose, *args, **kwargs):
        plans.append(T_table_camera)
        return plan(T_table_camera, *args, **kwargs)

    monkeypatch.setattr(cell.kinematics, "plan", counted)
    assert cell.move_to(a, motion=prepared_a) is prepared_a and plans == []
    assert np.allclose(cell.joint_positions(), prepared_a.q) and cell.last_motion is prepared_a
    ran = cell.move_to(b, motion=prepared_b)  # stale: it starts at the initial configuration, the arm is at a
    assert ran is not prepared_b and len(plans) == 1 and np.allclose(plans[0].matrix, b.matrix)
    assert np.allclose(cell.joint_positions(), ran.q)
    assert np.linalg.norm(cell.pose.translation - b.translation) < 1e-4
