"""The UR driver against an in-process controller speaking the ur_rtde interface, faults injected mid-motion."""

from __future__ import annotations

import importlib
import inspect
import math
import re
import threading

import numpy as np
import pytest

from devices.drivers.common import ArmFaultError
from devices.drivers.limits import LimitError
from devices.drivers.ur import UR_JOINTS, URArm, URConfig
from devices.protocols import DeviceError, JointArm
from devices.timeout import DeviceTimeoutError
from devices.trajectory import JointTrajectory
from tests.devices.drivers.fake_ur import CONTROLLERS, FakeController, FakeRTDEControl, FakeRTDEReceive

Q0 = np.array([0.0, -1.57, 1.57, -1.57, -1.57, 0.0])


def move(q0, q1, duration: float, points: int = 41) -> JointTrajectory:
    """A rest-to-rest cubic move from q0 to q1 (peak joint speed 1.5 * |q1 - q0| / duration)."""
    q0, q1 = np.asarray(q0, float), np.asarray(q1, float)
    t = np.linspace(0.0, duration, points)
    s = t / duration
    pos = q0 + (3 * s**2 - 2 * s**3)[:, None] * (q1 - q0)
    vel = ((6 * s - 6 * s**2) / duration)[:, None] * (q1 - q0)
    return JointTrajectory(UR_JOINTS, t, pos, vel)


@pytest.fixture
def controller():
    c = FakeController(q=Q0.copy())
    CONTROLLERS["ur-test"] = c
    yield c
    CONTROLLERS.pop("ur-test", None)


def arm(**overrides) -> URArm:
    settings = {
        "host": "ur-test",
        "max_joint_speed_deg": 90.0,
        "max_joint_acceleration_deg": 120.0,
        "speed_fraction": 1.0,
        "acceleration_fraction": 1.0,
    }
    settings.update(overrides)
    return URArm(URConfig(**settings), control_factory=FakeRTDEControl, receive_factory=FakeRTDEReceive)


def sent(controller: FakeController, name: str) -> list[tuple]:
    return [c for c in controller.calls if c[0] == name]


# ---------------------------------------------------------------------- the fake is the real interface


def _doc_params(doc: str, name: str) -> list[list[str]]:
    """Parameter names (without self) of every overload of ``name`` in a pybind11 docstring."""
    out = []
    for line in doc.splitlines():
        m = re.match(rf"^(?:\d+\. )?{name}\(self: [^,)]+(?:, (.*))?\) -> ", line.strip())
        if m:
            depth, parts, cur = 0, [], ""
            for ch in m.group(1) or "":
                depth += ch in "[("
                depth -= ch in "])"
                if ch == "," and depth == 0:
                    parts.append(cur)
                    cur = ""
                else:
                    cur += ch
            if cur.strip():
                parts.append(cur)
            out.append([p.split(":")[0].strip() for p in parts])
    return out


@pytest.mark.parametrize(
    ("fake", "module", "cls"),
    [
        (FakeRTDEControl, "rtde_control", "RTDEControlInterface"),
        (FakeRTDEReceive, "rtde_receive", "RTDEReceiveInterface"),
    ],
)
def test_the_fake_has_the_real_ur_rtde_signatures(fake, module, cls):
    real = getattr(importlib.import_module(module), cls)  # installed by the [ur] extra (make test)
    names = ["__init__"] + [n for n in vars(fake) if not n.startswith("_")]
    for name in names:
        assert hasattr(real, name), f"{cls} has no {name}"
        want = _doc_params(getattr(real, name).__doc__, name)
        got = [p for p in inspect.signature(getattr(fake, name)).parameters if p != "self"]
        assert want and got in want, f"{cls}.{name}: fake {got}, real {want}"


# ---------------------------------------------------------------------- normal motion


def test_connects_and_reads_the_joints(controller):
    a = arm()
    assert isinstance(a, JointArm)
    assert a.joint_names == UR_JOINTS
    assert np.allclose(a.joint_positions(), Q0)
    assert "UR at ur-test, path mode" in a.describe() and "-90.0" in a.describe()
    a.close()
    assert ("stopScript",) in controller.calls


def test_path_mode_sends_thinned_waypoints_at_the_scaled_speed(controller):
    a = arm(speed_fraction=0.5, acceleration_fraction=0.25, max_waypoints=5, blend_m=0.01)
    goal = Q0 + np.radians([10, -5, 5, 0, 0, 20])
    a.execute(move(Q0, goal, 1.0))
    (call,) = sent(controller, "moveJ")
    path, asynchronous = call[1], call[2]
    assert asynchronous is True
    assert len(path) == 5
    assert np.allclose(path[0][:6], Q0) and np.allclose(path[-1][:6], goal)
    assert all(p[6] == pytest.approx(math.radians(45.0)) for p in path)  # 0.5 x 90 deg/s
    assert all(p[7] == pytest.approx(math.radians(30.0)) for p in path)  # 0.25 x 120 deg/s^2
    assert [p[8] for p in path] == [0.01, 0.01, 0.01, 0.01, 0.0]
    assert np.allclose(a.joint_positions(), goal, atol=1e-9)


def test_servo_mode_streams_the_trajectory_slowed_at_the_controller_rate(controller):
    a = arm(
        mode="servo",
        speed_fraction=0.5,
        servo_rate_hz=125.0,
        max_joint_speed_deg=180.0,
        max_joint_acceleration_deg=400.0,
    )
    goal = Q0 + np.radians([8, 0, -8, 0, 0, 0])
    trajectory = move(Q0, goal, 0.2)
    a.execute(trajectory)
    servo = sent(controller, "servoJ")
    assert len(servo) == 51  # 0.2 s / 0.5 = 0.4 s at 125 Hz, both ends
    assert {round(c[2], 6) for c in servo} == {0.008}
    assert all(c[3] == 0.1 and c[4] == 300.0 for c in servo)
    mid = servo[25][1]  # t = 0.2 s of the slowed run = 0.1 s of the trajectory
    assert np.allclose(mid, trajectory.sample(0.1))
    assert sent(controller, "servoStop")
    assert ("connect", 125.0) in controller.calls
    waits = [c for c in controller.calls if c[0] in ("initPeriod", "waitPeriod")]
    assert [c[0] for c in waits] == ["initPeriod", "waitPeriod"] * 51  # paced by the controller's period
    assert all(w[1] == i[1] for i, w in zip(waits[::2], waits[1::2], strict=True))  # each waits from its own start
    assert np.allclose(a.joint_positions(), goal)


# ---------------------------------------------------------------------- faults mid-trajectory


@pytest.mark.parametrize("mode", ["path", "servo"])
@pytest.mark.parametrize(
    ("kind", "reason"),
    [
        ("protective_stop", "protective stop"),
        ("emergency_stop", "emergency stop"),
        ("disconnect", "lost connection to the controller"),
        ("script_stopped", "the control script is not running"),
    ],
)
def test_a_fault_mid_trajectory_raises_the_reason_with_the_last_joint_state(controller, mode, kind, reason):
    a = arm(mode=mode, max_joint_speed_deg=60.0, max_joint_acceleration_deg=200.0)
    goal = Q0 + np.radians([30, 0, 0, 0, 0, 0])
    trajectory = move(Q0, goal, 1.0)  # path mode: 30 deg at 60 deg/s = 0.5 s
    controller.inject(kind, 0.2 if mode == "path" else 0.5)
    with pytest.raises(ArmFaultError, match=re.escape(reason)) as info:
        a.execute(trajectory)
    err = info.value
    assert isinstance(err, DeviceError)
    assert err.reason.startswith(reason)
    q = err.joint_positions
    assert q is not None and q.shape == (6,)
    moved = math.degrees(q[0] - Q0[0])
    if mode == "path" and kind == "disconnect":  # the last state read before the link went down
        assert 0.0 < moved <= 12.1, moved
    elif mode == "path":  # the controller froze the joints 0.2 s into a 60 deg/s move
        assert moved == pytest.approx(12.0, abs=0.1)
    else:  # where the last servo command before the fault put them (how far depends on the machine's load)
        commanded = [c[1] for c in sent(controller, "servoJ")]
        assert any(np.allclose(q, c) for c in commanded) and 0.0 <= moved < 28.0, moved
    assert np.allclose(q[1:], Q0[1:])
    assert "last joints [" in str(err)


def test_stop_from_another_thread_halts_a_running_path(controller):
    a = arm(max_joint_speed_deg=30.0)
    goal = Q0 + np.radians([40, 0, 0, 0, 0, 0])  # 1.33 s, stopped after 0.2 s
    timer = threading.Timer(0.2, a.stop)
    timer.start()
    with pytest.raises(ArmFaultError, match="stopped on request") as info:
        a.execute(move(Q0, goal, 1.0))
    timer.join()
    assert sent(controller, "stopJ")
    q = info.value.joint_positions
    assert q is not None and 2.0 < math.degrees(q[0] - Q0[0]) < 38.0
    a.stop()  # nothing runs: harmless


def test_protective_stop_before_the_motion_sends_nothing(controller):
    a = arm()
    controller.safety_mode, controller.program_running = 3, False
    with pytest.raises(ArmFaultError, match=r"protective stop \(before the motion\)"):
        a.execute(move(Q0, Q0 + 0.1, 1.0))
    assert not sent(controller, "moveJ")


# ---------------------------------------------------------------------- limits before sending


def test_a_servo_trajectory_faster_than_the_limit_is_refused_before_sending(controller):
    a = arm(mode="servo", max_joint_speed_deg=60.0, speed_fraction=1.0)
    goal = Q0 + np.radians([0, 0, 0, 0, 0, 60])  # peak 1.5 * 60 / 1 = 90 deg/s
    with pytest.raises(LimitError, match=r"wrist_3_joint turns at 90.0 deg/s .* above max_joint_speed_deg 60.0"):
        a.execute(move(Q0, goal, 1.0, points=101))
    assert not sent(controller, "servoJ")
    slower = arm(mode="servo", max_joint_speed_deg=60.0, speed_fraction=0.5)
    slower.execute(move(Q0, goal, 1.0, points=11))  # the same trajectory at half speed keeps the limit
    assert np.allclose(slower.joint_positions(), goal)


def test_positions_outside_the_bounds_are_refused(controller):
    a = arm(joint_upper_deg=[360, 360, 360, 360, 360, 5])
    with pytest.raises(LimitError, match=r"wrist_3_joint at 5.37 deg \(t = 0.53 s\) is above its bound 5.00 deg"):
        a.execute(move(Q0, Q0 + np.radians([0, 0, 0, 0, 0, 10]), 1.0))
    assert not sent(controller, "moveJ")


def test_a_trajectory_not_starting_at_the_arm_is_refused(controller):
    a = arm()
    with pytest.raises(LimitError, match=r"starts 5.00 deg from the arm's joints"):
        a.execute(move(Q0 + np.radians([5, 0, 0, 0, 0, 0]), Q0, 1.0))
    assert not sent(controller, "moveJ")


def test_wrong_joint_names_are_a_value_error(controller):
    a = arm()
    names = ("a", "b", "c", "d", "e", "f")
    q = Q0.reshape(1, 6)
    with pytest.raises(ValueError, match=r"trajectory.joint_names: expected \['shoulder_pan_joint'"):
        a.execute(JointTrajectory(names, np.zeros(1), q, np.zeros_like(q)))


# ---------------------------------------------------------------------- connecting


def test_an_unreachable_controller_is_a_device_error_with_the_reason():
    with pytest.raises(DeviceError, match=r"cannot connect to UR controller nowhere .*Connection refused"):
        URArm(URConfig(host="nowhere"), control_factory=FakeRTDEControl, receive_factory=FakeRTDEReceive)


def test_a_controller_that_does_not_answer_times_out(controller):
    controller.connect_delay_s = 2.0
    with pytest.raises(DeviceTimeoutError, match=r"UR ur-test RTDE receive: no answer within 0.2 s"):
        arm(connect_timeout_s=0.2)


@pytest.mark.parametrize(
    ("overrides", "message"),
    [
        ({"host": ""}, r"devices.arm.host: required"),
        ({"speed_fraction": 1.5}, r"devices.arm.speed_fraction: must be in \(0, 1\]"),
        ({"mode": "teleport"}, r"devices.arm.mode: 'path' or 'servo'"),
        ({"joint_lower_deg": [0] * 5}, r"devices.arm.joint_lower_deg: must be 6 finite numbers"),
        ({"joint_lower_deg": [10] * 6, "joint_upper_deg": [0] * 6}, r"joint_upper_deg: must be above joint_lower_deg"),
        ({"lookahead_s": 0.5}, r"devices.arm.lookahead_s: must be in \[0.03, 0.2\]"),
    ],
)
def test_bad_config_names_the_field(overrides, message):
    settings = {"host": "ur-test", **overrides}
    with pytest.raises(ValueError, match=message):
        URConfig(**settings)


def test_path_mode_waits_for_an_async_operation_that_starts_late(controller):
    """ur_rtde acknowledges moveJ before the path starts; its progress stays at the idle value until then."""
    controller.start_delay_s = 0.15
    a = arm()
    goal = Q0 + np.radians([9, 0, 0, 0, 0, 0])  # 0.1 s at 90 deg/s, after the 0.15 s delay
    a.execute(move(Q0, goal, 1.0))
    assert np.allclose(a.joint_positions(), goal)
    a.execute(move(goal, Q0, 1.0))  # the next operation ends on the other idle value
    assert np.allclose(a.joint_positions(), Q0)
