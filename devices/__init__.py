"""Devices: the protocols a real driver implements, and simulated ones (a ray-cast camera, arm, turntable).

- ``protocols``  Camera / Arm / Turntable protocols, DeviceError and its kinds
- ``config``     CameraConfig, CellConfig, DeviceConfig
- ``mesh``       load_mesh, place_on_plate, sample_surface, MeshError
- ``builtins``   BUILTIN_OBJECTS, make_builtin, resolve_model
- ``cell``       Cell: frames (base / table / camera), reachability, move_to, capture; ScanCell, what a scan asks
- ``cellreach``  Reach: how the cell's arm reaches a view, SphereReach or UrdfArm (IK, collisions, trajectories)
- ``motion``     Motion: a planned move (plate angle, arm target, trajectory, duration); rz
- ``sim``        SimulatedCamera / Arm / Turntable, make_sim_cell
- ``drivers``    real hardware: RealSense, UR (RTDE), GRBL and Modbus turntables (vendor packages lazily)
- ``cellfile``   the cell file: which driver per device, hand-eye, arm base, allow_auto
- ``rig``        open_rig / check_devices: the cell file's devices opened, checked, stopped
- ``hwcell``     hardware_cell: the kinematic Cell on a rig's devices
- ``movestream`` a real cell's capture during moves: streamed frames placed by the joint states at their stamps

Importing ``devices`` does not import open3d (the simulated camera does, when built).
"""

from devices.builtins import BUILTIN_OBJECTS, make_builtin, resolve_model
from devices.cell import Cell, Motion, ScanCell
from devices.cellreach import Reach, SphereReach, UrdfArm
from devices.config import CameraConfig, CellConfig, DeviceConfig
from devices.mesh import MeshError, load_mesh, place_on_plate, sample_surface
from devices.protocols import Arm, Camera, CaptureError, DeviceError, Turntable, UnreachableError
from devices.sim import SimulatedArm, SimulatedCamera, SimulatedTurntable, make_sim_cell, sim_cell_from_config

__all__ = [
    "BUILTIN_OBJECTS",
    "Arm",
    "Camera",
    "CameraConfig",
    "CaptureError",
    "Cell",
    "CellConfig",
    "DeviceConfig",
    "DeviceError",
    "MeshError",
    "Motion",
    "Reach",
    "ScanCell",
    "SimulatedArm",
    "SimulatedCamera",
    "SimulatedTurntable",
    "SphereReach",
    "Turntable",
    "UnreachableError",
    "UrdfArm",
    "load_mesh",
    "make_builtin",
    "make_sim_cell",
    "place_on_plate",
    "resolve_model",
    "sample_surface",
    "sim_cell_from_config",
]
