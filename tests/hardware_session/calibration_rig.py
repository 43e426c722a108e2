"""The fake rig of the calibration tests: the RealSense driver plays the sphere target's depth images rendered from
where the camera really is (``T_table_camera @ E`` for each calibration pose, the cell file's hand-eye off by E),
beside the fake UR controller and GRBL firmware (tests/devices/drivers/rigfixtures.py); the cell file lets the arm
move fast and the fakes move faster still (:func:`play_fast`)."""

from __future__ import annotations

import math
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path

from devices.calibration import DEFAULT_TARGET, calibration_poses
from devices.calibration.poses import CalibrationPose
from devices.config import CameraConfig
from devices.sim import SimulatedCamera
from planner.types import Pose
from tests.devices.drivers.rigfixtures import FakeCell, cell_toml, fake_hardware_cell, play_fast
from tests.devices.drivers.rsfixtures import DEPTH_UNIT

CAMERA = CameraConfig(width=320, height=240, fx=280.0, fy=280.0, cx=159.5, cy=119.5, min_depth=0.05, max_depth=3.0)
ANGLES = (0.0, 120.0, -120.0)
"""The plate angles of the calibration, degrees."""
FAST_ARM = (
    "max_joint_speed_deg = 360\nspeed_fraction = 1.0\nacceleration_fraction = 1.0\nmax_joint_acceleration_deg = 1440"
)


@contextmanager
def calibration_rig(folder: Path, E: Pose) -> Iterator[tuple[FakeCell, list[CalibrationPose]]]:
    """(the fake cell, the calibration poses at :data:`ANGLES` in the order the images play)."""
    poses = calibration_poses(DEFAULT_TARGET, math.pi, plate_angles_deg=ANGLES)
    camera = SimulatedCamera(DEFAULT_TARGET.mesh(), CAMERA, plate_radius=0.2)
    depths = [camera.render(p.T_table_camera @ E) for p in poses]
    k = CAMERA.intrinsics
    with fake_hardware_cell(folder, depths, k, depth_unit=DEPTH_UNIT) as fake:
        fake.path.write_text(cell_toml(fake.grbl.port, k, arm_speed=FAST_ARM))
        play_fast(fake)  # the poses reached are checked, not how long the moves take
        yield fake, poses
