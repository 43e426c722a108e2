"""The ROS 2 fake cell (``tests/ros2/fake_cell.py``) as a context manager: a cell file on loopback and the process.

:func:`fake_ros2_cell` writes ``folder/cell.toml`` (``driver = "ros2"`` for the camera, the arm and the turntable,
the arm mounted like the simulator's UR5 beside the plate), on a DDS domain of its own, the loopback interface and
unicast discovery to 127.0.0.1 (no multicast: the tests never touch a network, and parallel test processes do not
hear each other), starts the fake cell process on it and yields a :class:`FakeRos2Cell`; the process ends on exit.
"""

from __future__ import annotations

import json
import os
import subprocess
import sys
import threading
from collections.abc import Iterator
from contextlib import contextmanager
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from devices.arm.config import ArmConfig
from devices.config import CameraConfig

ROOT = Path(__file__).resolve().parents[2]

CAMERA = CameraConfig(width=160, height=120, fx=140.0, fy=140.0, cx=79.5, cy=59.5, min_depth=0.05, max_depth=3.0)
"""A small camera (quick to render and send) that still sees the object well from every candidate."""

ARM_SPEED_DEG = 180.0
"""The cell file's ``max_joint_speed_deg``: the UR5's URDF limit (180 deg/s). The fake executes a trajectory in real
time, so a move's wall time is its duration (it cannot play one faster: the driver checks every joint state against
where the trajectory should be by then); the tests check where the arm settles and what the camera sees there, not
how fast it got there (tests/ros2/test_ros2_scan.py, with :data:`FAST_ARM` and a faster plate, ``table_scale``)."""

TABLE_SPEED_DEG = 360.0
"""The turntable's speed, deg/s, in the cell file and in the fake (a half turn in half a second)."""

FAST_ARM = ArmConfig(velocity_scale=1.0, acceleration_limit_deg=2880.0)
"""The planning arm of the tests' sessions on the fake cell: the URDF's full joint speeds (kept within
:data:`ARM_SPEED_DEG` by the cell file) and a ramp of a sixteenth of a second to full speed, so the planned
trajectories are short in time."""

_next_domain = [0]


def fresh_domain() -> int:
    """A DDS domain for one fake cell: from the process id (the parallel test workers differ) and a counter."""
    _next_domain[0] += 1
    return 1 + (os.getpid() * 7 + _next_domain[0]) % 200


def cell_toml(domain: int, *, arm: str = "", camera: str = "", turntable: str = "", allow_auto: bool = False) -> str:
    """A ros2 cell file on ``domain`` over loopback; ``arm`` / ``camera`` / ``turntable``: extra lines of a section."""
    net = f'domain_id = {domain}\ninterface = "lo"\npeers = ["127.0.0.1"]'
    timeout = "" if "timeout_s" in camera else "timeout_s = 3.0"
    return f"""
[devices]
allow_auto = {"true" if allow_auto else "false"}

[devices.camera]
driver = "ros2"
{net}
min_depth = 0.05
max_depth = 3.0
{timeout}
{camera}

[devices.arm]
driver = "ros2"
{net}
max_joint_speed_deg = {ARM_SPEED_DEG:g}
{arm}

[devices.turntable]
driver = "ros2"
{net}
speed_deg = {TABLE_SPEED_DEG:g}
{turntable}

[devices.hand_eye]
translation = [0.0, 0.0, 0.05]

[devices.arm_base]
translation = [-0.85, 0.0, 0.0]
"""


@dataclass
class FakeRos2Cell:
    """The cell file, its domain and the fake cell process (:meth:`command` injects a fault)."""

    path: Path
    domain: int
    process: subprocess.Popen[str]
    lock: threading.Lock

    def command(self, line: str) -> None:
        """Send a fault line (``silent_camera``, ``ignore_trajectory``, ``jump``, ``encoding rgb8``, ``pause_joints S``,
        ``stale_frame``, ``reset``: see ``tests/ros2/fake_cell.py``)."""
        with self.lock:
            assert self.process.stdin is not None and self.process.stdout is not None
            self.process.stdin.write(line + "\n")
            self.process.stdin.flush()
            answer = self.process.stdout.readline().strip()
        assert answer == "ok", f"the fake cell answered {answer!r} to {line!r}"


@contextmanager
def fake_ros2_cell(
    folder: Path,
    camera: CameraConfig = CAMERA,
    rate_hz: float = 15.0,
    camera_section: str = "",
    table_scale: float = 1.0,
    **sections: Any,
) -> Iterator[FakeRos2Cell]:
    """See the module docstring; ``camera_section``: extra lines of ``[devices.camera]``; ``table_scale``: the fake
    plate turns this many times faster than the cell file's :data:`TABLE_SPEED_DEG` (the driver waits until it is
    there and settled; its speed only sets the turn's timeout); ``sections``: the other keywords of
    :func:`cell_toml`."""
    domain = fresh_domain()
    path = folder / "cell.toml"
    path.write_text(cell_toml(domain, camera=camera_section, **sections))
    spec = {
        "width": camera.width,
        "height": camera.height,
        "fx": camera.fx,
        "fy": camera.fy,
        "cx": camera.cx,
        "cy": camera.cy,
        "min_depth": camera.min_depth,
        "max_depth": camera.max_depth,
        "rate_hz": rate_hz,
        "turntable_speed_deg": TABLE_SPEED_DEG * table_scale,
    }
    env = {**os.environ, "PYTHONPATH": str(ROOT), "OMP_NUM_THREADS": "1"}
    process = subprocess.Popen(
        [sys.executable, "-m", "tests.ros2.fake_cell", str(path), json.dumps(spec)],
        cwd=ROOT,
        env=env,
        stdin=subprocess.PIPE,
        stdout=subprocess.PIPE,
        text=True,
    )
    try:
        assert process.stdout is not None
        line = process.stdout.readline().strip()
        assert line == "ready", f"the fake ROS 2 cell did not start (said {line!r}, exit {process.poll()})"
        yield FakeRos2Cell(path, domain, process, threading.Lock())
    finally:
        if process.stdin is not None:
            process.stdin.close()
        try:
            process.wait(timeout=10)
        except subprocess.TimeoutExpired:
            process.kill()
            process.wait()
