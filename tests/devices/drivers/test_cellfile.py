"""The cell file: drivers by name, their configs, the hand-eye and arm-base poses, one-line errors."""

from __future__ import annotations

import math
import textwrap
from pathlib import Path

import numpy as np
import pytest

from devices.cellfile import load_cell_file, parse_cell
from devices.drivers.grbl import GrblConfig
from devices.drivers.realsense import RealSenseConfig
from devices.drivers.registry import SimCameraConfig
from devices.drivers.ur import URConfig
from planner.types import Pose

FULL = """
[voxel]
resolution = 0.005     # other tables are for other readers

[devices]
allow_auto = true

[devices.camera]
driver = "realsense"
width = 848
height = 480
filters = ["spatial", "temporal"]
average = 3
playback = "recordings/scan.db3"

[devices.arm]
driver = "ur"
host = "192.168.1.10"
speed_fraction = 0.5
max_joint_speed_deg = 45      # an integer for a float field
mode = "servo"

[devices.turntable]
driver = "grbl"
port = "/dev/ttyUSB0"
units_per_degree = 2
home_on_connect = true

[devices.hand_eye]
translation = [0.0, 0.05, 0.04]
rotation_deg = [0.0, 0.0, 90.0]

[devices.arm_base]
translation = [-0.45, 0.0, 0.0]
quaternion_wxyz = [0.0, 0.0, 0.0, 1.0]
"""


def write(tmp_path: Path, text: str) -> Path:
    path = tmp_path / "cell.toml"
    path.write_text(text)
    return path


def test_a_full_cell_file(tmp_path):
    cell = load_cell_file(write(tmp_path, FULL))
    assert cell.source.endswith("cell.toml") and cell.allow_auto is True
    assert cell.camera is not None and cell.camera.driver == "realsense"
    cam = cell.camera.config
    assert isinstance(cam, RealSenseConfig)
    assert (cam.width, cam.height, cam.filters, cam.average) == (848, 480, ("spatial", "temporal"), 3)
    assert cam.playback == str(tmp_path / "recordings" / "scan.db3")  # relative to the cell file
    assert cell.arm is not None and isinstance(cell.arm.config, URConfig)
    assert cell.arm.config.max_joint_speed_deg == 45.0 and cell.arm.config.mode == "servo"
    assert cell.turntable is not None and isinstance(cell.turntable.config, GrblConfig)
    assert cell.turntable.config.units_per_degree == 2.0 and cell.turntable.config.home_on_connect
    assert [d.kind for d in cell.devices()] == ["camera", "arm", "turntable"]
    # hand-eye: yaw 90 deg maps the camera's x axis onto the flange's y axis
    assert np.allclose(cell.hand_eye.rotation @ [1, 0, 0], [0, 1, 0])
    assert np.allclose(cell.hand_eye.translation, [0.0, 0.05, 0.04])
    assert np.allclose(cell.arm_base.rotation, np.diag([-1.0, -1.0, 1.0]))  # 180 deg about z
    # T_base_camera = T_base_armbase @ T_armbase_flange @ T_flange_camera
    T_armbase_flange = Pose(np.eye(3), np.array([0.3, 0.0, 0.5]))
    T = cell.T_base_camera(T_armbase_flange)
    assert np.allclose(T.translation, [-0.45 - 0.3 - 0.0, 0.0 - 0.05, 0.5 + 0.04])


def test_a_sim_rehearsal_cell_and_the_defaults(tmp_path):
    cell = parse_cell({"devices": {"camera": {"driver": "sim", "model": "bunny", "width": 160, "height": 120}}})
    assert cell.arm is None and cell.turntable is None and cell.allow_auto is False
    assert cell.camera is not None and isinstance(cell.camera.config, SimCameraConfig)
    assert cell.camera.config.model == "bunny"  # a built-in name is not made a path
    assert np.allclose(cell.hand_eye.matrix, np.eye(4)) and np.allclose(cell.arm_base.matrix, np.eye(4))


@pytest.mark.parametrize(
    ("text", "message"),
    [
        ("[voxel]\nresolution = 0.01\n", r"^devices: the cell file needs a \[devices\] table"),
        ("[devices]\nspeed = 1\n", r"^devices.speed: unknown setting \(known: camera, arm, turntable, hand_eye"),
        ("[devices]\nallow_auto = 1\n", r"^devices.allow_auto: expected true/false, got 1$"),
        (
            "[devices.camera]\nwidth = 640\n",
            r"^devices.camera.driver: required \(one of realsense, replay, ros2, sim\)$",
        ),
        ('[devices.arm]\ndriver = "kuka"\n', r"^devices.arm.driver: unknown driver 'kuka' \(known: ros2, ur\)$"),
        ('[devices.arm]\ndriver = "ur"\n', r"^devices.arm.host: required"),
        ('[devices.arm]\ndriver = "ur"\nhost = "a"\nspeed = 2\n', r"^devices.arm.speed: unknown setting \(known: "),
        (
            '[devices.arm]\ndriver = "ur"\nhost = "a"\nspeed_fraction = "fast"\n',
            r"^devices.arm.speed_fraction: expected a number, got 'fast'$",
        ),
        (
            '[devices.arm]\ndriver = "ur"\nhost = "a"\nspeed_fraction = true\n',
            r"^devices.arm.speed_fraction: expected a number, got True$",
        ),
        ('[devices.turntable]\ndriver = "grbl"\nport = 5\n', r"^devices.turntable.port: expected a string, got 5$"),
        ('[devices.camera]\ndriver = "sim"\nwidth = 0\n', r"^devices.camera.width: must be an integer >= 1, got 0$"),
        ('[devices.camera]\ndriver = "realsense"\nfilters = ["median"]\n', r"^devices.camera.filters: unknown filter"),
        ("[devices.hand_eye]\ntranslation = [0, 0]\n", r"^devices.hand_eye.translation: must be 3 finite numbers"),
        ("[devices.hand_eye]\nrotation_deg = [0, 0, 'x']\n", r"^devices.hand_eye.rotation_deg: must be 3 finite"),
        (
            "[devices.arm_base]\nquaternion_wxyz = [1, 1, 0, 0]\n",
            r"^devices.arm_base.quaternion_wxyz: must be a unit quaternion, norm is 1.4142$",
        ),
        (
            "[devices.arm_base]\nrotation_deg = [0, 0, 0]\nquaternion_wxyz = [1, 0, 0, 0]\n",
            r"^devices.arm_base: give rotation_deg or quaternion_wxyz, not both$",
        ),
        ("[devices.arm_base]\nyaw = 3\n", r"^devices.arm_base.yaw: unknown setting"),
        ("[devices\n", r"cell.toml: invalid TOML"),
        ("[devices]\nmove_capture_hz = -1\n", r"^devices.move_capture_hz: frames per second in \[0, 60\], got -1$"),
        ('[devices]\nmove_capture_hz = "fast"\n', r"^devices.move_capture_hz: frames per second"),
    ],
)
def test_bad_cell_files_are_one_line_naming_the_field(tmp_path, text, message):
    with pytest.raises(ValueError, match=message) as info:
        load_cell_file(write(tmp_path, text))
    assert "\n" not in str(info.value)


def test_the_cell_files_rate_of_capture_during_moves_wins_over_the_servers(tmp_path):
    from devices.config import CellConfig
    from devices.hwcell import arm_cell_config

    mount = "[devices.arm_base]\ntranslation = [-0.45, 0.0, 0.0]\n"
    cell = load_cell_file(write(tmp_path, "[devices]\nmove_capture_hz = 2.5\n" + mount))
    assert cell.move_capture_hz == 2.5
    assert arm_cell_config(cell, CellConfig(move_capture_hz=5.0)).move_capture_hz == 2.5
    unset = load_cell_file(write(tmp_path, "[devices]\nallow_auto = false\n" + mount))
    assert unset.move_capture_hz is None
    assert arm_cell_config(unset, CellConfig(move_capture_hz=5.0)).move_capture_hz == 5.0


def test_a_missing_file_is_a_value_error(tmp_path):
    with pytest.raises(ValueError, match=r"nope.toml: cannot read the cell file"):
        load_cell_file(tmp_path / "nope.toml")


def test_rotation_is_extrinsic_xyz_degrees(tmp_path):
    cell = parse_cell({"devices": {"hand_eye": {"rotation_deg": [90.0, 0.0, 90.0]}}})
    # first 90 about x (y -> z), then 90 about the fixed z (x -> y): the camera's y axis ends on +z
    R = cell.hand_eye.rotation
    assert np.allclose(R @ [0, 1, 0], [0, 0, 1], atol=1e-12)
    assert np.allclose(R @ [1, 0, 0], [0, 1, 0], atol=1e-12)
    assert math.isclose(np.linalg.det(R), 1.0)


def test_arm_mount_is_position_and_yaw_of_an_upright_arm_base():
    cell = parse_cell({"devices": {"arm_base": {"translation": [-0.8, 0.1, 0.02], "rotation_deg": [0, 0, 30]}}})
    (x, y, z), yaw = cell.arm_mount()
    assert (x, y, z) == (-0.8, 0.1, 0.02) and yaw == pytest.approx(30.0)
    tilted = parse_cell({"devices": {"arm_base": {"rotation_deg": [5, 0, 0]}}})
    with pytest.raises(ValueError, match=r"devices.arm_base: tilted 5.00 deg from upright"):
        tilted.arm_mount()


def test_the_examples_in_docs_hardware_md_parse():
    import re
    import tomllib

    text = (Path(__file__).resolve().parents[3] / "docs" / "hardware.md").read_text()
    blocks = [b for b in re.findall(r"```toml\n(.*?)```", text, flags=re.S) if "[devices" in b]  # cell files
    assert len(blocks) == 2
    full = parse_cell(tomllib.loads(blocks[0]))
    assert [d.driver for d in full.devices()] == ["realsense", "ur", "grbl"]
    assert full.arm is not None and full.arm.config.joint_upper_deg[1] == 0.0
    modbus = parse_cell(tomllib.loads(textwrap.dedent(blocks[1])))
    assert modbus.turntable is not None and modbus.turntable.driver == "modbus"
