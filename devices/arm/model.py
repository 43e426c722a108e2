"""The arm's kinematic model: a URDF loaded with Pinocchio, mounted in the cell, with the camera on its flange.

Frames: ``base`` is the cell's lab frame (z-up, origin at the centre of the plate top, see
``devices/cell.py``); the arm's URDF root sits at ``T_base_mount`` (``CellConfig.arm_base`` and
``ArmConfig.base_yaw_deg``); the camera (OpenCV axes) is at ``T_flange_camera`` from the flange frame.
The mount is baked into the Pinocchio model, so its forward kinematics give ``T_base_*`` directly.

:func:`load_arm` validates everything it is given and raises a one-line ``ValueError`` naming the field
(``arm.urdf``, ``arm.flange_frame``, ``arm.joint_lower_deg`` ...): nothing half-built is returned.
"""

from __future__ import annotations

import contextlib
import functools
import importlib.metadata
import math
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import NDArray

from devices.arm.config import ArmConfig
from planner.types import Pose


def example_robot_data_share() -> Path:
    """The ``share`` folder of the installed ``example-robot-data`` package (holds ``example-robot-data/robots``)."""
    try:
        dist = importlib.metadata.distribution("example-robot-data")
    except importlib.metadata.PackageNotFoundError:
        raise ValueError(
            "arm.urdf: the arm presets need the example-robot-data package (pip install example-robot-data)"
        ) from None
    return Path(str(dist.locate_file("cmeel.prefix/share")))


def resolve_urdf(config: ArmConfig) -> tuple[Path, Path | None, list[str]]:
    """(URDF path, SRDF path or None, package dirs) for ``config``; ValueError naming the field if missing.

    A preset's files come from the installed ``example-robot-data``, whose ``package://example-robot-data/...``
    mesh paths resolve from its ``cmeel.prefix/share`` (added to the package dirs). A URDF file gets its folder
    and three parents, and the installed ``share`` folder too (a copy of a preset's URDF still finds its meshes).
    """
    preset = config.preset
    if preset is not None:
        share = example_robot_data_share()
        robots = share / "example-robot-data" / "robots"
        urdf = robots / preset.urdf
        srdf: Path | None = (
            Path(config.srdf).expanduser() if config.srdf else (robots / preset.srdf if preset.srdf else None)
        )
        dirs = [str(share)]
    else:
        urdf = Path(config.urdf).expanduser()
        srdf = Path(config.srdf).expanduser() if config.srdf else None
        dirs = [str(urdf.parent), *(str(p) for p in urdf.parents[:3])]
        with contextlib.suppress(ValueError):
            dirs.append(str(example_robot_data_share()))
    if not urdf.is_file():
        raise ValueError(f"arm.urdf: no such file {str(urdf)!r}")
    if srdf is not None and not srdf.is_file():
        raise ValueError(f"arm.srdf: no such file {str(srdf)!r}")
    return urdf, srdf, [*config.package_dirs, *dirs]


@dataclass(frozen=True, eq=False)
class ArmModel:
    """A loaded arm: Pinocchio model (mount baked in) with a ``camera`` frame, its collision geometry, limits.

    model / geometry: ``pinocchio.Model`` / ``pinocchio.GeometryModel`` (collision meshes of the URDF plus
    the camera body). camera_frame: id of the camera frame. lower / upper: (n,) joint limits, radians.
    velocity / acceleration: (n,) limits of a move, rad/s and rad/s^2. srdf: the SRDF used (or None).
    """

    config: ArmConfig
    model: Any
    geometry: Any
    camera_frame: int
    lower: NDArray[np.float64]
    upper: NDArray[np.float64]
    velocity: NDArray[np.float64]
    acceleration: NDArray[np.float64]
    T_base_mount: Pose
    urdf_path: Path
    srdf_path: Path | None
    package_dirs: tuple[str, ...]
    locked: tuple[tuple[str, float], ...] = ()
    """The joints removed from the model (not the arm's: grippers, fingers) and the value each is fixed at."""

    @property
    def joint_names(self) -> tuple[str, ...]:
        """The actuated joints, in the order of every configuration vector."""
        return tuple(self.model.names[i] for i in range(1, self.model.njoints))

    @property
    def nq(self) -> int:
        return int(self.model.nq)

    def within_limits(self, q: NDArray[np.float64], tol: float = 1e-9) -> bool:
        """Whether (n,) ``q`` is inside the joint limits."""
        return bool(np.all(q >= self.lower - tol) and np.all(q <= self.upper + tol))

    def camera_pose(self, q: NDArray[np.float64], data: Any | None = None) -> Pose:
        """``T_base_camera`` at configuration (n,) ``q`` (forward kinematics)."""
        import pinocchio as pin  # pyright: ignore[reportMissingImports]  (under cmeel.prefix)

        buffers: Any = data if data is not None else self.model.createData()
        pin.framesForwardKinematics(self.model, buffers, np.asarray(q, dtype=np.float64))
        M = buffers.oMf[self.camera_frame]
        rotation, translation = np.array(M.rotation), np.array(M.translation)
        if not (np.isfinite(rotation).all() and np.isfinite(translation).all()):
            return Pose(rotation, translation)  # raises, naming the field
        # forward kinematics of finite joints is a proper rotation: Pose's orthonormality check (about 0.1 ms, a
        # cold plan asks for hundreds) is left out, the arrays made read-only as Pose's own are
        rotation.setflags(write=False)
        translation.setflags(write=False)
        return Pose.trusted(rotation, translation)

    def frame_pose(self, name: str, q: NDArray[np.float64]) -> Pose:
        """``T_base_<name>`` of any frame of the model at configuration (n,) ``q``."""
        import pinocchio as pin  # pyright: ignore[reportMissingImports]  (under cmeel.prefix)

        if not self.model.existFrame(name):
            raise ValueError(f"frame: no frame {name!r} in the arm model")
        data = self.model.createData()
        pin.framesForwardKinematics(self.model, data, np.asarray(q, dtype=np.float64))
        M = data.oMf[self.model.getFrameId(name)]
        return Pose(np.array(M.rotation), np.array(M.translation))


def mount_pose(arm_base: tuple[float, float, float], base_yaw_deg: float) -> Pose:
    """``T_base_mount``: the arm's root at ``arm_base``, turned ``base_yaw_deg`` about z."""
    c, s = math.cos(math.radians(base_yaw_deg)), math.sin(math.radians(base_yaw_deg))
    return Pose(np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]]), np.asarray(arm_base, dtype=np.float64))


@functools.lru_cache(maxsize=8)
def load_arm(config: ArmConfig, arm_base: tuple[float, float, float]) -> ArmModel:
    """Build the arm of ``config`` mounted at ``arm_base`` (base frame, metres). ValueError naming the field.

    Cached per (config, base) in the process (many sessions share one cell geometry): the returned model is
    never changed after loading; users make their own ``model.createData()`` / geometry copies.
    """
    import coal  # pyright: ignore[reportMissingImports]  (under cmeel.prefix)
    import pinocchio as pin  # pyright: ignore[reportMissingImports]  (under cmeel.prefix)

    urdf, srdf, dirs = resolve_urdf(config)
    try:
        model = pin.buildModelFromUrdf(str(urdf))
    except Exception as exc:  # Pinocchio raises ValueError / RuntimeError with the parser's text
        raise ValueError(f"arm.urdf: cannot load {urdf.name} ({_first_line(exc)})") from None
    if model.nq == 0:
        raise ValueError(f"arm.urdf: {urdf.name} has no movable joint")
    if model.nq != model.nv or any(model.joints[i].nq != 1 for i in range(1, model.njoints)):
        raise ValueError(f"arm.urdf: {urdf.name} has continuous or multi-axis joints (only 1-DoF joints with limits)")
    flange_frame = config.flange
    if not model.existFrame(flange_frame):
        frames = [f.name for f in model.frames][-4:]
        raise ValueError(f"arm.flange_frame: no frame {flange_frame!r} in {urdf.name} (last frames: {frames})")
    try:
        geometry = pin.buildGeomFromUrdf(model, str(urdf), pin.GeometryType.COLLISION, package_dirs=dirs)
    except Exception as exc:
        raise ValueError(f"arm.urdf: cannot load the collision meshes of {urdf.name} ({_first_line(exc)})") from None
    model, geometry, locked = _lock_joints(pin, config, model, geometry, urdf.name)

    lower, upper = _limits(config, model)
    T_base_mount = mount_pose(arm_base, config.base_yaw_deg)
    M_mount = pin.SE3(T_base_mount.rotation, T_base_mount.translation)
    for j in range(1, model.njoints):  # joints hanging from the root get the mount (geometry follows its joint)
        if model.parents[j] == 0:
            model.jointPlacements[j] = M_mount * model.jointPlacements[j]
    for i in range(len(model.frames)):
        if model.frames[i].parentJoint == 0:
            frame = model.frames[i]
            frame.placement = M_mount * frame.placement
            model.frames[i] = frame
    for i in range(geometry.ngeoms):
        if geometry.geometryObjects[i].parentJoint == 0:
            geometry.geometryObjects[i].placement = M_mount * geometry.geometryObjects[i].placement

    flange_id = _frame_id(pin, model, flange_frame)
    flange = model.frames[flange_id]
    T_fc = config.T_flange_camera_matrix
    M_joint_camera = flange.placement * pin.SE3(T_fc[:3, :3], T_fc[:3, 3])
    camera_frame = model.addFrame(pin.Frame("camera", flange.parentJoint, flange_id, M_joint_camera, pin.OP_FRAME))
    sx, sy, sz = config.camera_size
    if sx > 0 and sy > 0 and sz > 0:  # the body lies behind the optical centre
        M_box = M_joint_camera * pin.SE3(np.eye(3), np.array([0.0, 0.0, -0.5 * sz]))
        geometry.addGeometryObject(pin.GeometryObject("camera", flange.parentJoint, M_box, coal.Box(sx, sy, sz)))

    scale = config.velocity_scale
    velocity = np.array(model.velocityLimit, dtype=np.float64) * scale
    if not np.all(np.isfinite(velocity)) or np.any(velocity <= 0):
        velocity = np.where(np.isfinite(velocity) & (velocity > 0), velocity, math.pi * scale)
    acceleration = np.full(model.nv, math.radians(config.acceleration_limit_deg))
    return ArmModel(
        config=config,
        model=model,
        geometry=geometry,
        camera_frame=camera_frame,
        lower=lower,
        upper=upper,
        velocity=velocity,
        acceleration=acceleration,
        T_base_mount=T_base_mount,
        urdf_path=urdf,
        srdf_path=srdf,
        package_dirs=tuple(dirs),
        locked=locked,
    )


def _lock_joints(
    pin: Any, config: ArmConfig, model: Any, geometry: Any, urdf_name: str
) -> tuple[Any, Any, tuple[tuple[str, float], ...]]:
    """(model, geometry, ((joint, value), ...)) with the locked joints of ``config`` (:attr:`ArmConfig.locks`)
    removed at their values (``pinocchio.buildReducedModel``); ValueError naming the field for an unknown joint or
    a value outside its limits."""
    locks = config.locks
    if not locks:
        return model, geometry, ()
    q_ref = pin.neutral(model)
    ids, values = [], []
    for name, value in locks:
        if not model.existJointName(name):
            known = [model.names[i] for i in range(1, model.njoints)]
            raise ValueError(f"arm.locked_joints: no joint {name!r} in {urdf_name} (joints: {known})")
        jid = model.getJointId(name)
        iq = model.joints[jid].idx_q
        lo, hi = float(model.lowerPositionLimit[iq]), float(model.upperPositionLimit[iq])
        if value is None:
            value = 0.5 * (lo + hi) if math.isfinite(lo) and math.isfinite(hi) and not lo <= 0.0 <= hi else 0.0
            value = min(max(value, lo), hi) if math.isfinite(lo) and math.isfinite(hi) else value
        if math.isfinite(lo) and math.isfinite(hi) and not lo - 1e-9 <= value <= hi + 1e-9:
            raise ValueError(f"arm.locked_positions: {name} = {value} is outside its limits [{lo}, {hi}]")
        q_ref[iq] = value
        ids.append(jid)
        values.append((name, float(value)))
    if len(ids) >= model.nq:
        raise ValueError(f"arm.locked_joints: every joint of {urdf_name} is locked")
    reduced, reduced_geometry = pin.buildReducedModel(model, geometry, ids, q_ref)
    return reduced, reduced_geometry, tuple(values)


def _limits(config: ArmConfig, model: Any) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    lower = np.array(model.lowerPositionLimit, dtype=np.float64)
    upper = np.array(model.upperPositionLimit, dtype=np.float64)
    n = model.nq
    for name, values in (("joint_lower_deg", config.joint_lower_deg), ("joint_upper_deg", config.joint_upper_deg)):
        if values and len(values) != n:
            raise ValueError(f"arm.{name}: need {n} values (one per joint), got {len(values)}")
    if config.joint_lower_deg:
        lower = np.maximum(lower, np.radians(config.joint_lower_deg))
    if config.joint_upper_deg:
        upper = np.minimum(upper, np.radians(config.joint_upper_deg))
    lower = np.where(np.isfinite(lower), lower, -2 * math.pi)
    upper = np.where(np.isfinite(upper), upper, 2 * math.pi)
    bad = np.flatnonzero(lower >= upper)
    if len(bad):
        j = int(bad[0])
        field = "arm.joint_lower_deg" if config.joint_lower_deg or config.joint_upper_deg else "arm.urdf"
        raise ValueError(
            f"{field}: joint {model.names[j + 1]} has inverted limits "
            f"(lower {math.degrees(lower[j]):.1f} >= upper {math.degrees(upper[j]):.1f} degrees)"
        )
    return lower, upper


def _frame_id(pin: Any, model: Any, name: str) -> int:
    """The id of frame ``name``: the link's (BODY) frame when a joint and a link share the name (Unitree's Z1)."""
    if model.existFrame(name, pin.FrameType.BODY):
        return int(model.getFrameId(name, pin.FrameType.BODY))
    return int(model.getFrameId(name))


def _first_line(exc: BaseException) -> str:
    text = str(exc).strip().splitlines()
    return text[0] if text else type(exc).__name__


def check_arm(config: ArmConfig) -> None:
    """Load the arm of ``config`` once (cached) so a bad URDF, SRDF or flange frame fails at start-up with its
    one-line ``ValueError`` naming the field, not when the first session is made. Call it with
    ``CellConfig.arm`` when ``CellConfig.kinematics`` is 'urdf'."""
    load_arm(config, config.mount)
