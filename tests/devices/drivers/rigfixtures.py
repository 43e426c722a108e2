"""A whole fake hardware cell for tests: a RealSense recording, the fake UR controller, the fake GRBL firmware.

``fake_hardware_cell(folder, depths, intrinsics)`` writes ``depths`` into ``folder/scan.db3`` with
librealsense's recorder, starts the GRBL firmware on a pseudo terminal, registers an in-process UR
controller under the host ``ur-cell``, swaps the UR driver's RTDE classes for the fake ones
(``registry.override``), writes ``folder/cell.toml`` naming all three (``driver = "realsense"``,
``"ur"``, ``"grbl"``) and yields a :class:`FakeCell`. Everything is undone on exit. A session test can
open the cell with ``devices.rig.open_rig(load_cell_file(cell.path))`` or pass the path to a command
in the same process.
"""

from __future__ import annotations

from collections.abc import Iterator, Sequence
from contextlib import contextmanager
from dataclasses import dataclass
from pathlib import Path

import numpy as np
from numpy.typing import NDArray

from devices.drivers.registry import override
from devices.drivers.rsrecord import write_depth_recording
from devices.drivers.ur import URArm
from planner.types import Intrinsics
from tests.devices.drivers.fake_grbl import FakeGrbl
from tests.devices.drivers.fake_ur import CONTROLLERS, FakeController, FakeRTDEControl, FakeRTDEReceive

UR_HOST = "ur-cell"

FAST_PLAYBACK = 4.0
"""How much faster than real time :func:`play_fast` makes the fakes move."""


@dataclass
class FakeCell:
    """The cell file and the fakes behind it (to inspect them or inject faults)."""

    path: Path
    grbl: FakeGrbl
    controller: FakeController


def cell_toml(
    port: str,
    intrinsics: Intrinsics,
    *,
    arm: bool = True,
    arm_speed: str = "max_joint_speed_deg = 30",
    camera: str = "",
) -> str:
    """A cell file for the recording ``scan.db3`` next to it, the GRBL on ``port`` and (if ``arm``) the fake UR
    (``arm_speed``: lines for its section) mounted like the simulator's UR5, beside the plate; ``camera``: more
    lines of the camera's section. The fake firmware
    answers from a thread of the test's process, which a busy machine can hold for longer than half a second:
    a status request may take up to 5 s (the tests of a silent GRBL wait for its banner, ``startup_s``)."""
    k = intrinsics
    text = f"""
[devices]
allow_auto = false

[devices.camera]
driver = "realsense"
width = {k.width}
height = {k.height}
min_depth = 0.05
max_depth = 3.0
timeout_s = 1.0
playback = "scan.db3"
{camera}

[devices.turntable]
driver = "grbl"
port = "{port}"
command_timeout_s = 5.0
poll_s = 0.01
"""
    if arm:
        text += f"""
[devices.arm]
driver = "ur"
host = "{UR_HOST}"
{arm_speed}

[devices.hand_eye]
translation = [0.0, 0.0, 0.05]

[devices.arm_base]
translation = [-0.85, 0.0, 0.0]
"""
    return text


def play_fast(cell: FakeCell) -> None:
    """Make the fake UR play its paths and the fake GRBL turn :data:`FAST_PLAYBACK` times faster than commanded: for
    the session and calibration tests, which check where the arm and plate go and what the camera sees there, not
    how long a move takes (the drivers wait for the devices to say they arrived; a move's timeout is only a ceiling).
    The move capture tests, which check frame stamps along a move, keep real time."""
    cell.controller.time_scale = FAST_PLAYBACK
    cell.grbl.rate *= FAST_PLAYBACK


@contextmanager
def fake_hardware_cell(
    folder: Path,
    depths: Sequence[NDArray[np.float32]],
    intrinsics: Intrinsics,
    *,
    depth_unit: float = 1e-4,
    arm_speed: str = "max_joint_speed_deg = 30",
    camera: str = "",
    timestamps_ms: Sequence[float] | None = None,
    domains: Sequence[str] | None = None,
) -> Iterator[FakeCell]:
    """See the module docstring. ``depths``: (H, W) float32 metres each, played back in order (``timestamps_ms``,
    ``domains``: their timestamps, as :func:`write_depth_recording`); ``camera``: more lines of its section."""
    write_depth_recording(
        folder / "scan.db3", depths, intrinsics, depth_unit=depth_unit, timestamps_ms=timestamps_ms, domains=domains
    )
    controller = FakeController()
    CONTROLLERS[UR_HOST] = controller
    try:
        with FakeGrbl() as grbl:
            path = folder / "cell.toml"
            path.write_text(cell_toml(grbl.port, intrinsics, arm_speed=arm_speed, camera=camera))

            def open_ur(config):
                return URArm(config, control_factory=FakeRTDEControl, receive_factory=FakeRTDEReceive)

            with override("arm", "ur", open_ur):
                yield FakeCell(path, grbl, controller)
    finally:
        CONTROLLERS.pop(UR_HOST, None)
