"""Named arms that work out of the box: the robots of the ``example-robot-data`` package, with what a URDF alone
does not say (data, no code).

Each :class:`ArmPreset` names its URDF and SRDF (paths inside ``example-robot-data/robots``; their ``package://``
mesh paths resolve from the installed package's ``cmeel.prefix/share``), the flange frame the camera is mounted
on, the joints that are not the arm's (grippers, fingers) and the value each is locked at, a collision-free home,
a default mount that reaches the paper's hemisphere (found with ``nbv arms check NAME``, see
:mod:`devices.arm.mount`) and the camera mount. ``ArmConfig.urdf`` takes a preset's name; every field the config
leaves at its "the preset's" default (``flange_frame = ''``, ``home_deg = ()``, ``base = ()``, ...) comes from
here. A URDF file that is no preset gets the defaults of :data:`FILE_DEFAULTS`.

Kinova's arm (continuous joints) is not a preset: the arm model refuses continuous joints.
"""

from __future__ import annotations

from dataclasses import dataclass

DEFAULT_T_FLANGE_CAMERA: tuple[tuple[float, ...], ...] = (
    (1.0, 0.0, 0.0, 0.0),
    (0.0, 1.0, 0.0, 0.0),
    (0.0, 0.0, 1.0, 0.05),
    (0.0, 0.0, 0.0, 1.0),
)
"""The camera 5 cm in front of the flange, looking along the flange's +z (OpenCV +z forward)."""


@dataclass(frozen=True)
class ArmPreset:
    """One named arm. Paths are relative to ``example-robot-data/robots`` of the installed package."""

    name: str
    """What ``--arm`` and ``arm.urdf`` take."""
    title: str
    """The robot, for lists and the page."""
    urdf: str
    """The URDF, relative to ``example-robot-data/robots``."""
    srdf: str
    """The SRDF whose ``disable_collisions`` pairs are not checked ('' = none)."""
    flange_frame: str
    """The URDF frame the camera is mounted on."""
    home_deg: tuple[float, ...]
    """A collision-free configuration of the arm's joints (the locked ones left out), degrees."""
    base: tuple[float, float, float]
    """The default mount (URDF root) in the cell's base frame, metres: beside the plate, on the -x side."""
    locked_joints: tuple[tuple[str, float], ...] = ()
    """Joints that are not the arm's (grippers, fingers) and the value each is locked at (radians or metres, the
    URDF's unit): they are removed from the model, never planned for and never move."""
    T_flange_camera: tuple[tuple[float, ...], ...] = DEFAULT_T_FLANGE_CAMERA
    """The camera mount: the camera pose (OpenCV axes) in the flange frame."""
    cell_scale: float = 1.0
    """The cell size it suits, as a fraction of the paper's: objects of ``0.2 * cell_scale`` m (``--size``) at
    ``cell_scale`` times the default working distance. 1 for the full-size arms."""
    dof: int = 6
    """Joints the arm moves (after locking)."""
    note: str = ""
    """One line for ``nbv arms``: what it is, what it suits."""


UR_HOME = (0.0, -90.0, 90.0, -90.0, -90.0, 0.0)
"""A UR's elbow-up pose with the flange looking down."""

PRESETS: dict[str, ArmPreset] = {
    p.name: p
    for p in (
        ArmPreset(
            name="ur5",
            title="Universal Robots UR5",
            urdf="ur_description/urdf/ur5_robot.urdf",
            srdf="ur_description/srdf/ur5.srdf",
            flange_frame="tool0",
            home_deg=UR_HOME,
            base=(-0.85, 0.0, 0.0),
            note="the default: 0.85 m reach; the two top parallels of the default hemisphere are out of reach "
            "at this mount (as in the paper's cell)",
        ),
        ArmPreset(
            name="ur10",
            title="Universal Robots UR10",
            urdf="ur_description/urdf/ur10_robot.urdf",
            srdf="ur_description/srdf/ur5.srdf",  # same link names: the UR5's adjacent-pair list applies
            flange_frame="tool0",
            home_deg=UR_HOME,
            base=(-0.85, 0.0, 0.0),
            note="1.3 m reach",
        ),
        ArmPreset(
            name="panda",
            title="Franka Emika Panda",
            urdf="panda_description/urdf/panda.urdf",
            srdf="panda_description/srdf/panda.srdf",
            flange_frame="panda_hand_tcp",
            home_deg=(0.0, -45.0, 0.0, -135.0, 0.0, 90.0, 45.0),
            base=(-0.6, 0.0, 0.0),
            locked_joints=(("panda_finger_joint1", 0.02), ("panda_finger_joint2", 0.02)),
            dof=7,
            note="7 joints, 0.855 m reach; the fingers are locked half open, the camera looks out past them",
        ),
        ArmPreset(
            name="xarm7",
            title="UFACTORY xArm7",
            urdf="xarm_description/urdf/xarm7.urdf",
            srdf="xarm_description/srdf/xarm7.srdf",
            flange_frame="link_eef",
            home_deg=(0.0, -30.0, 0.0, 60.0, 0.0, 90.0, 0.0),
            base=(-0.6, 0.0, 0.0),
            dof=7,
            note="7 joints, 0.7 m reach",
        ),
        ArmPreset(
            name="z1",
            title="Unitree Z1",
            urdf="z1_description/urdf/z1.urdf",
            srdf="z1_description/srdf/z1.srdf",
            flange_frame="gripperStator",
            home_deg=(0.0, 60.0, -60.0, 0.0, 0.0, 0.0),
            base=(-0.45, 0.0, 0.0),
            locked_joints=(("jointGripper", 0.0),),
            cell_scale=0.6,
            note="a low-cost teaching arm, 0.74 m reach: suits a small cell (objects of about 12 cm, "
            "--size 0.12, working distance 0.6x the default)",
        ),
    )
}
"""The presets by name; ``ur5`` is the default arm."""

DEFAULT_PRESET = "ur5"

FILE_DEFAULTS = ArmPreset(
    name="",
    title="a URDF file",
    urdf="",
    srdf="",
    flange_frame="tool0",
    home_deg=(),
    base=(-0.85, 0.0, 0.0),
)
"""What a URDF file that is no preset gets for the fields left at their defaults (home () = all zeros, clipped to
the limits)."""


def preset_named(name: str) -> ArmPreset:
    """The preset ``name``; ValueError listing the presets."""
    preset = PRESETS.get(name)
    if preset is None:
        raise ValueError(f"arm: no preset {name!r} (presets: {', '.join(PRESETS)}; or the path of a URDF file)")
    return preset


def preset_of(urdf: str) -> ArmPreset | None:
    """The preset ``urdf`` names (``ArmConfig.urdf``), or None for a file."""
    return PRESETS.get(urdf)
