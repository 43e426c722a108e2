"""Write a calibration into the cell file: ``[devices.hand_eye]``, ``[devices.arm_base]`` and
``[devices.turntable_axis]``, the old file kept.

The hand-eye section gets the estimated ``T_flange_camera``. The plate-centre (base) frame is defined by the
turntable axis, so the arm base is moved by the measured axis offset: the new base origin is where the axis crosses
the plate top (``arm_base.translation -= axis_point``). The axis' direction goes into ``[devices.turntable_axis]``
as data: a real cell places its frames about it (devices/hwcell.py, ``HardwareCell.pose``); the arm's planner keeps
a vertical axis (a tilt of more than about 0.2 degrees is still worth levelling the turntable for; more than
``MAX_AXIS_TILT_DEG`` is refused). Only these sections change; every other line (and comment) of the file stays.
The new text is parsed as a cell file before anything is written; the old file is copied to
``<name>.<UTC time>.bak`` first and the new one replaces it atomically.
"""

from __future__ import annotations

import datetime
import os
import shutil
import tomllib
from pathlib import Path

import numpy as np
from scipy.spatial.transform import Rotation

from devices.calibration.result import CalibrationResult
from devices.cellfile import load_cell_file, parse_cell
from planner.types import Pose


def _numbers(values: np.ndarray, digits: int) -> str:
    return "[" + ", ".join(f"{float(v):.{digits}f}" for v in values) + "]"


def _section(name: str, pose: Pose, comments: list[str]) -> list[str]:
    rpy = Rotation.from_matrix(pose.rotation).as_euler("xyz", degrees=True)
    return [
        f"[devices.{name}]",
        *(f"# {c}" for c in comments),
        f"translation = {_numbers(pose.translation, 6)}",
        f"rotation_deg = {_numbers(rpy, 5)}",
        "",
    ]


def _replace_section(lines: list[str], name: str, block: list[str]) -> list[str]:
    header = f"[devices.{name}]"
    start = next((i for i, line in enumerate(lines) if line.strip().split("#")[0].strip() == header), None)
    if start is None:
        return [*lines, *([""] if lines and lines[-1].strip() else []), *block]
    end = next((i for i in range(start + 1, len(lines)) if lines[i].lstrip().startswith("[")), len(lines))
    return [*lines[:start], *block, *lines[end:]]


def calibrated_cell_text(text: str, result: CalibrationResult, arm_base: Pose, stamp: str = "") -> str:
    """``text`` (a cell file) with the hand-eye and arm-base sections of ``result`` (``arm_base``: the file's
    current ``T_base_armbase``, in the frame the calibration ran in)."""
    shift = np.array([result.axis_point_base[0], result.axis_point_base[1], 0.0])
    new_base = Pose(arm_base.rotation, arm_base.translation - shift)
    when = f" {stamp}" if stamp else ""
    hand_eye = _section(
        "hand_eye",
        result.T_flange_camera,
        [
            f"calibrated{when}: +-{result.hand_eye_std_mm:.2f} mm, +-{result.hand_eye_std_deg:.3f} deg (1 sigma), "
            f"residual rms {result.rms_mm:.2f} mm over {len(result.labels)} captures"
        ],
    )
    base = _section(
        "arm_base",
        new_base,
        [
            f"calibrated{when}: moved by the turntable axis offset {_numbers(-shift[:2] * 1000, 2)} mm "
            f"(+-{result.axis_std_mm:.2f} mm)",
        ],
    )
    axis = [
        "[devices.turntable_axis]",
        f"# calibrated{when}: tilt {result.axis_tilt_deg:.3f} deg (+-{result.axis_std_deg:.3f}) from the vertical",
        f"direction = {_numbers(result.axis_direction_base, 7)}",
        "",
    ]
    lines = text.splitlines()
    lines = _replace_section(lines, "hand_eye", hand_eye)
    lines = _replace_section(lines, "arm_base", base)
    lines = _replace_section(lines, "turntable_axis", axis)
    return "\n".join(lines).rstrip("\n") + "\n"


def write_calibration(path: str | Path, result: CalibrationResult) -> Path:
    """Write ``result`` into the cell file at ``path`` (see the module docstring); returns the backup's path.
    ValueError (nothing written) when the file is not a valid cell file or the new text would not be one."""
    path = Path(path)
    cell = load_cell_file(path)
    stamp = datetime.datetime.now(datetime.UTC).strftime("%Y%m%dT%H%M%SZ")
    text = calibrated_cell_text(path.read_text(encoding="utf-8"), result, cell.arm_base, stamp)
    try:
        parse_cell(tomllib.loads(text), path.parent, str(path))
    except (tomllib.TOMLDecodeError, ValueError) as exc:
        raise ValueError(f"{path}: cannot write the calibration into this cell file ({exc})") from None
    backup = path.with_name(f"{path.name}.{stamp}.bak")
    shutil.copy2(path, backup)
    tmp = path.with_name(f".{path.name}.calibrating")
    tmp.write_text(text, encoding="utf-8")
    os.replace(tmp, path)
    return backup
