"""The arm's configuration: which robot, where its flange and camera are, how fast it may move, how it plans.

A frozen dataclass in the style of ``devices/config.py``: every default is documented at its field, a bad
value raises a one-line ``ValueError`` naming the field (``arm.T_flange_camera: ...``). Lengths in metres,
angles in degrees (a config edge). Whether the URDF loads and has the flange frame is checked when the
model is built (:func:`devices.arm.model.load_arm`), before anything else of the cell exists.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from devices.arm.presets import DEFAULT_T_FLANGE_CAMERA, FILE_DEFAULTS, ArmPreset, preset_of
from planner.validate import finite, integer, require

__all__ = ["DEFAULT_T_FLANGE_CAMERA", "ArmConfig", "rigid_matrix"]


def rigid_matrix(name: str, value: object) -> NDArray[np.float64]:
    """(4, 4) float64 from ``value`` (nested sequences); ValueError naming ``name`` unless a rigid transform."""
    try:
        T = np.array(value, dtype=np.float64)
    except (TypeError, ValueError):
        raise ValueError(f"{name}: must be a 4x4 matrix of numbers, got {value!r}") from None
    require(T.shape == (4, 4), f"{name}: must be a 4x4 matrix, got shape {T.shape}")
    require(bool(np.all(np.isfinite(T))), f"{name}: has non-finite entries")
    require(bool(np.allclose(T[3], [0.0, 0.0, 0.0, 1.0], atol=1e-9)), f"{name}: last row must be [0, 0, 0, 1]")
    R = T[:3, :3]
    error = float(np.abs(R.T @ R - np.eye(3)).max())
    require(
        error < 1e-6 and np.linalg.det(R) > 0,
        f"{name}: not a rigid transform (rotation part not orthonormal with det +1, error {error:.2g})",
    )
    return T


@dataclass(frozen=True)
class ArmConfig:
    """A robot arm from a URDF with a depth camera on its flange; its mount is ``CellConfig.arm_base``."""

    urdf: str = "ur5"
    """An arm preset ('ur5', 'ur10', 'panda', 'xarm7', 'z1': ``devices/arm/presets.py``, ``nbv arms``) or the path
    of a URDF file. A preset brings its SRDF, flange frame, locked joints, home, mount and camera mount: the
    fields below left at their defaults take the preset's."""
    srdf: str = ""
    """SRDF whose ``disable_collisions`` pairs are not checked ('' = the preset's; none for a URDF file).
    Geometries of adjacent links are never checked against each other."""
    package_dirs: tuple[str, ...] = ()
    """Where ``package://`` mesh paths of the URDF are looked up (the URDF's folder and its parents are added)."""
    flange_frame: str = ""
    """The URDF frame the camera is mounted on ('' = the preset's; 'tool0' for a URDF file)."""
    T_flange_camera: tuple[tuple[float, ...], ...] = DEFAULT_T_FLANGE_CAMERA
    """Hand-eye calibration: the camera pose (OpenCV axes) in the flange frame, a 4x4 rigid transform (metres).
    The default (5 cm in front of the flange) stands for the preset's camera mount."""
    camera_size: tuple[float, float, float] = (0.09, 0.03, 0.03)
    """The camera body, a box behind the optical centre (x, y, z extents in the camera frame), metres;
    checked for collisions like the links."""
    base: tuple[float, ...] = ()
    """Position of the arm's mount (URDF root) in the cell's base frame, metres, 3 numbers (() = the preset's
    mount; (-0.85, 0, 0) for a URDF file): beside the turntable. The UR5's (-0.85, 0, 0) reaches most but not
    all of the paper's hemisphere at the default working distance (the two top parallels are out of reach);
    ``nbv arms check NAME`` searches a mount. The reach-sphere cell uses ``cell.arm_base`` instead."""
    home_deg: tuple[float, ...] = ()
    """Configuration the arm starts from, degrees, one per (unlocked) joint (() = the preset's collision-free
    home, all zeros for a URDF file; a wrong length = all zeros; clipped to the limits). The UR5's is its
    elbow-up pose with the flange looking down."""
    locked_joints: tuple[str, ...] = ()
    """Joints of the URDF that are not the arm's (grippers, fingers): removed from the model at
    ``locked_positions``, never planned for, never moved (() = the preset's; none for a URDF file)."""
    locked_positions: tuple[float, ...] = ()
    """The value of each of ``locked_joints``, in the URDF's unit (radians, or metres for a prismatic joint);
    () = each joint's value in the middle of its limits (or 0 inside them)."""
    base_yaw_deg: float = 0.0
    """Rotation of the arm's mount about the vertical axis, degrees."""
    joint_lower_deg: tuple[float, ...] = ()
    """Tighter lower joint limits than the URDF's, degrees, one per joint (() = the URDF's)."""
    joint_upper_deg: tuple[float, ...] = ()
    """Tighter upper joint limits than the URDF's, degrees, one per joint (() = the URDF's)."""
    velocity_scale: float = 0.5
    """Fraction of the URDF's joint velocity limits a move may use."""
    acceleration_limit_deg: float = 180.0
    """Joint acceleration limit, degrees/s^2, every joint (URDFs do not give one)."""
    turntable_speed_deg: float = 45.0
    """Turntable speed, degrees/s (for the move duration; the simulated plate turns at once)."""
    turn_while_moving: bool = False
    """Turn the plate while the arm runs its trajectory when every configuration on the arm's path stands clear of
    the vertical cylinder the padded object box sweeps about the plate's axis (no plate angle can bring the box
    into the arm, ``CollisionWorld.sweep_free``): the move then takes the longer of the turn and the trajectory,
    not their sum. False (the default): the plate turns, then the arm moves."""
    plate_offsets_deg: tuple[float, ...] = (0.0, -30.0, 30.0, -60.0, 60.0, -90.0, 90.0)
    """Plate angles tried per view: the view's azimuth minus the arm's azimuth after turning, degrees.
    The first reachable one decides reachability; a move takes the one with the shortest move."""
    table_height: float = -0.06
    """Top of the table the turntable stands on, below the plate top (z = 0), metres (0 = no table)."""
    object_padding: float = 0.02
    """Margin added to the object's box for collisions, metres."""
    ik_iterations: int = 60
    """Damped least squares iterations per IK seed."""
    ik_seeds: int = 4
    """IK attempts per pose and plate angle (the current configuration, a neighbour's solution, fixed ones)."""
    ik_tolerance: float = 1e-4
    """IK converged when the position error is below this (metres) and the rotation error below 10x (radians)."""
    path_resolution_deg: float = 2.0
    """Largest joint step between collision checks along a path, degrees."""
    planning_checks: int = 20000
    """Budget of one RRT-Connect query (a move whose straight line is blocked): at most this many collision
    checks of configurations, then the move is refused ('no_path'). A count, not a time, so the result does
    not depend on the machine's load (about 40 us of CPU per check on the UR5: 20000 = about 0.8 s)."""
    planning_time: float = 30.0
    """Hang guard of one RRT-Connect query, wall-clock seconds: the query gives up ('no_path') if it runs this
    long before its ``planning_checks`` are spent. Keep it generous: when it decides, results depend on load."""

    def __post_init__(self) -> None:
        require(isinstance(self.urdf, str) and self.urdf.strip() != "", f"arm.urdf: 'ur5' or a path, got {self.urdf!r}")
        require(isinstance(self.srdf, str), f"arm.srdf: must be a path or '', got {self.srdf!r}")
        require(
            isinstance(self.flange_frame, str), f"arm.flange_frame: must be a frame name, got {self.flange_frame!r}"
        )
        locked = self.locked_joints
        require(
            isinstance(locked, list | tuple) and all(isinstance(j, str) and j for j in locked),
            f"arm.locked_joints: must be a list of joint names, got {locked!r}",
        )
        object.__setattr__(self, "locked_joints", tuple(locked))
        values = self.locked_positions
        require(
            isinstance(values, list | tuple) and finite(*values),
            f"arm.locked_positions: must be a list of finite numbers, got {values!r}",
        )
        require(
            len(values) in (0, len(self.locked_joints)),
            f"arm.locked_positions: need one value per locked joint ({len(self.locked_joints)}), got {len(values)}",
        )
        object.__setattr__(self, "locked_positions", tuple(float(v) for v in values))
        dirs = self.package_dirs
        require(
            isinstance(dirs, list | tuple) and all(isinstance(d, str) for d in dirs),
            f"arm.package_dirs: must be a list of paths, got {dirs!r}",
        )
        object.__setattr__(self, "package_dirs", tuple(dirs))
        T = rigid_matrix("arm.T_flange_camera", self.T_flange_camera)
        object.__setattr__(self, "T_flange_camera", tuple(tuple(float(v) for v in row) for row in T))
        size = tuple(self.camera_size) if isinstance(self.camera_size, list | tuple) else ()
        require(
            len(size) == 3 and finite(*size) and all(s >= 0 for s in size),
            f"arm.camera_size: must be 3 numbers >= 0, got {self.camera_size!r}",
        )
        object.__setattr__(self, "camera_size", tuple(float(s) for s in size))
        for name in ("joint_lower_deg", "joint_upper_deg", "plate_offsets_deg"):
            v = getattr(self, name)
            require(
                isinstance(v, list | tuple) and finite(*v), f"arm.{name}: must be a list of finite numbers, got {v!r}"
            )
            object.__setattr__(self, name, tuple(float(x) for x in v))
        require(len(self.plate_offsets_deg) >= 1, "arm.plate_offsets_deg: need at least one plate angle")
        try:
            base = tuple(float(v) for v in self.base)
        except (TypeError, ValueError):
            raise ValueError(f"arm.base: must be 3 numbers, got {self.base!r}") from None
        require(len(base) in (0, 3) and finite(*base), f"arm.base: must be 3 finite numbers, got {self.base!r}")
        object.__setattr__(self, "base", base)
        require(
            isinstance(self.home_deg, list | tuple) and finite(*self.home_deg),
            f"arm.home_deg: must be a list of finite numbers, got {self.home_deg!r}",
        )
        object.__setattr__(self, "home_deg", tuple(float(x) for x in self.home_deg))
        require(finite(self.base_yaw_deg), f"arm.base_yaw_deg: must be finite, got {self.base_yaw_deg!r}")
        require(
            finite(self.velocity_scale) and 0 < self.velocity_scale <= 1,
            f"arm.velocity_scale: must be in (0, 1], got {self.velocity_scale!r}",
        )
        for name in ("acceleration_limit_deg", "turntable_speed_deg", "ik_tolerance", "path_resolution_deg"):
            v = getattr(self, name)
            require(finite(v) and v > 0, f"arm.{name}: must be > 0, got {v!r}")
        require(
            finite(self.planning_time) and 0 < self.planning_time <= 60,
            f"arm.planning_time: must be in (0, 60] seconds, got {self.planning_time!r}",
        )
        require(
            isinstance(self.turn_while_moving, bool),
            f"arm.turn_while_moving: true or false, got {self.turn_while_moving!r}",
        )
        require(
            finite(self.table_height) and self.table_height <= 0, "arm.table_height: must be <= 0 (below the plate)"
        )
        require(
            finite(self.object_padding) and self.object_padding >= 0,
            f"arm.object_padding: must be >= 0, got {self.object_padding!r}",
        )
        for name in ("ik_iterations", "ik_seeds", "planning_checks"):
            v = getattr(self, name)
            require(integer(v) and v >= 1, f"arm.{name}: must be an integer >= 1, got {v!r}")

    @property
    def preset(self) -> ArmPreset | None:
        """The preset ``urdf`` names, or None for a URDF file."""
        return preset_of(self.urdf)

    @property
    def defaults(self) -> ArmPreset:
        """Where the fields left at their defaults come from: the preset, or :data:`FILE_DEFAULTS` for a file."""
        return self.preset or FILE_DEFAULTS

    @property
    def flange(self) -> str:
        """The flange frame: ``flange_frame``, else the preset's."""
        return self.flange_frame or self.defaults.flange_frame

    @property
    def mount(self) -> tuple[float, float, float]:
        """The arm's mount in the cell's base frame, metres: ``base``, else the preset's."""
        x, y, z = self.base or self.defaults.base
        return (x, y, z)

    @property
    def home(self) -> tuple[float, ...]:
        """The start configuration, degrees: ``home_deg``, else the preset's."""
        return self.home_deg or self.defaults.home_deg

    @property
    def locks(self) -> tuple[tuple[str, float | None], ...]:
        """(joint, value or None = the middle of its limits) of every locked joint: ``locked_joints``, else the
        preset's."""
        if not self.locked_joints:
            return tuple(self.defaults.locked_joints)
        values: tuple[float | None, ...] = self.locked_positions or (None,) * len(self.locked_joints)
        return tuple(zip(self.locked_joints, values, strict=True))

    @property
    def T_flange_camera_matrix(self) -> NDArray[np.float64]:
        """(4, 4) float64 the hand-eye transform (the preset's camera mount when ``T_flange_camera`` is the
        default)."""
        if self.T_flange_camera == DEFAULT_T_FLANGE_CAMERA:
            return np.array(self.defaults.T_flange_camera, dtype=np.float64)
        return np.array(self.T_flange_camera, dtype=np.float64)
