"""Tests against real devices: ``pytest -m hardware`` with the device addresses in the environment.

Deselected by default (``addopts = -m 'not hardware'``). Selected without the environment variable they
FAIL, saying what to set: a hardware run that silently skipped would look like a pass. Pick one device
with ``-k``: ``pytest -m hardware -k ur``.

- ``NBV_UR_HOST``: a UR controller (or URSim) in remote control, arm powered on and brakes released.
  The test moves wrist 3 by +2 degrees and back at 10 % speed: clear the cell first.
- ``NBV_GRBL_PORT``: the turntable's serial port; it turns the plate +10 degrees and back.
- ``NBV_REALSENSE``: ``1`` for the first camera found, or a serial number.
"""

from __future__ import annotations

import math
import os

import numpy as np
import pytest

from devices.drivers.grbl import GrblConfig, GrblTurntable
from devices.drivers.realsense import RealSenseCamera, RealSenseConfig
from devices.drivers.ur import UR_JOINTS, URArm, URConfig
from devices.trajectory import JointTrajectory

pytestmark = pytest.mark.hardware


def need(name: str, what: str) -> str:
    value = os.environ.get(name, "")
    if not value:
        pytest.fail(f"set {name} to {what} to run this hardware test (see docs/hardware.md)")
    return value


def test_ur_reads_joints_and_moves_wrist_3_by_two_degrees_and_back():
    arm = URArm(URConfig(host=need("NBV_UR_HOST", "the controller's address"), speed_fraction=0.1))
    try:
        q0 = arm.joint_positions()
        assert q0.shape == (6,) and np.all(np.abs(q0) < 2 * math.pi + 0.1)
        assert arm.fault() is None
        q1 = q0.copy()
        q1[5] += math.radians(2.0)
        t = np.array([0.0, 1.0])
        there = JointTrajectory(UR_JOINTS, t, np.stack([q0, q1]), np.zeros((2, 6)))
        back = JointTrajectory(UR_JOINTS, t, np.stack([q1, q0]), np.zeros((2, 6)))
        arm.execute(there)
        assert np.allclose(arm.joint_positions(), q1, atol=math.radians(0.5))
        arm.execute(back)
        assert np.allclose(arm.joint_positions(), q0, atol=math.radians(0.5))
    finally:
        arm.close()


def test_grbl_turntable_turns_ten_degrees_and_back():
    with GrblTurntable(GrblConfig(port=need("NBV_GRBL_PORT", "the turntable's serial port"))) as table:
        a0 = table.angle
        table.rotate_to(a0 + math.radians(10.0))
        assert math.isclose(math.remainder(table.angle - a0, 2 * math.pi), math.radians(10.0), abs_tol=1e-3)
        table.rotate_to(a0)
        assert math.isclose(math.remainder(table.angle - a0, 2 * math.pi), 0.0, abs_tol=1e-3)


def test_realsense_live_capture_has_depth_and_plausible_intrinsics():
    which = need("NBV_REALSENSE", "1 (first camera) or a serial number")
    config = RealSenseConfig(serial="" if which == "1" else which, average=3, max_depth=4.0)
    with RealSenseCamera(config) as camera:
        k = camera.intrinsics
        assert (k.width, k.height) == (640, 480)
        assert 300 < k.fx < 1000 and abs(k.cx - 320) < 40 and abs(k.cy - 240) < 40
        assert 0 < camera.depth_scale < 0.01
        frame = camera.capture()
        assert np.count_nonzero(frame.depth) > 0.1 * frame.depth.size
