"""The kinematic :class:`devices.cell.Cell` on real devices: what a session drives on hardware.

:func:`hardware_cell` puts the opened devices of a :class:`devices.rig.Rig` into the same ``Cell`` the
simulator uses, with the arm model (``devices/arm``, the UR5 by default) configured from the cell file:
the hand-eye transform, the arm's mount and the driver's joint bounds. Planning, IK, collision checks and
trajectories then run on our side exactly as in simulation; ``Cell.move_to`` turns the real plate and
sends the trajectory to the real arm, ``Cell.capture`` takes a real image and places it by forward
kinematics of the joints the controller reports.
"""

from __future__ import annotations

import dataclasses
from typing import Any

from devices.cell import Cell
from devices.cellfile import CellFile
from devices.config import CellConfig
from devices.rig import Rig


def arm_cell_config(cell: CellFile, base: CellConfig) -> CellConfig:
    """``base`` with the URDF arm model configured from the cell file (see the table in docs/hardware.md).

    ``T_flange_camera`` = the hand-eye transform, ``base`` / ``base_yaw_deg`` = the arm mount; with a UR arm
    also its joint limits and ``acceleration_limit_deg`` (at most ``max_joint_acceleration_deg``).
    ValueError naming the field (a tilted ``devices.arm_base``).
    """
    position, yaw = cell.arm_mount()
    changes: dict[str, Any] = {
        "T_flange_camera": tuple(tuple(float(v) for v in row) for row in cell.hand_eye.matrix),
        "base": position,
        "base_yaw_deg": yaw,
    }
    config = cell.arm.config if cell.arm is not None else None
    if config is not None and hasattr(config, "joint_lower_deg"):
        changes["joint_lower_deg"] = tuple(config.joint_lower_deg)
        changes["joint_upper_deg"] = tuple(config.joint_upper_deg)
    if config is not None and hasattr(config, "max_joint_acceleration_deg"):
        changes["acceleration_limit_deg"] = min(base.arm.acceleration_limit_deg, config.max_joint_acceleration_deg)
    return dataclasses.replace(base, kinematics="urdf", arm=dataclasses.replace(base.arm, **changes))


def hardware_cell(rig: Rig, cell_config: CellConfig | None = None) -> Cell:
    """A Cell of ``rig``'s camera, arm and turntable.

    cell_config: the plate, the initial view and the arm model (``cell_config.arm``: URDF, planning
    settings); its ``T_flange_camera``, ``base``, ``base_yaw_deg`` are replaced by the cell file's
    ``hand_eye`` and ``arm_base`` and, for a UR arm, its joint bounds by ``[devices.arm]``'s, so plans and
    the driver agree. ValueError when a device is missing, the arm base is tilted, or the model's joints
    are not the driver's.
    """
    from devices.arm.kinematics import ArmKinematics

    cell_config = cell_config if cell_config is not None else CellConfig()
    missing = [kind for kind in ("camera", "arm", "turntable") if getattr(rig, kind) is None]
    if missing:
        raise ValueError(f"devices.{missing[0]}: a cell needs a camera, an arm and a turntable")
    cell_config = arm_cell_config(rig.cell, cell_config)
    arm_config = cell_config.arm
    kinematics = ArmKinematics(arm_config, cell_config.plate_radius, cell_config.plate_thickness)
    if tuple(kinematics.joint_names) != tuple(rig.arm.joint_names):
        raise ValueError(
            f"devices.arm: the arm model's joints {list(kinematics.joint_names)} are not the driver's "
            f"{list(rig.arm.joint_names)}"
        )
    return Cell(rig.camera, rig.arm, rig.turntable, cell_config, kinematics=kinematics)
