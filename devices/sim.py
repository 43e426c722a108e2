"""Simulated devices: a ray-casting depth camera, an arm and a turntable that just keep their state.

The camera renders the object mesh and the turntable plate (a cylinder of
``plate_radius`` whose top is z = 0, so it hides the object's underside) in the
table frame with open3d's ``RaycastingScene``. Rays go through pixel centres at
integer pixel coordinates, the convention of ``DepthFrame.points_camera``; each
ray's direction has camera-frame z = 1, so the hit distance is the planar
z-depth directly. (``RaycastingScene.create_rays_pinhole`` also scales its rays
to z = 1, but puts pixel centres at u + 0.5, half a pixel off this convention,
so the rays are built here.)

Fault injection: set ``fail_next`` on any simulated device to an exception; its
next action raises it (and clears it) without changing the state.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from typing import Any

import numpy as np
import trimesh
from numpy.typing import NDArray

from devices.arm.sim_arm import SimulatedJointArm
from devices.cell import Cell, rz, wrap_angle
from devices.config import CameraConfig, CellConfig, DeviceConfig
from devices.protocols import CaptureError, DeviceError
from planner.types import DepthFrame, Intrinsics, Pose


def plate_mesh(radius: float, thickness: float, sections: int = 96) -> trimesh.Trimesh:
    """The turntable plate: a cylinder of ``radius`` with its top at z = 0, its bottom at z = -thickness."""
    plate = trimesh.creation.cylinder(radius=radius, height=thickness, sections=sections)
    plate.apply_translation((0.0, 0.0, -0.5 * thickness))
    return plate


class SimulatedCamera:
    """A pinhole depth camera rendering ``mesh`` (table frame) plus the plate.

    mesh: the object, or None for an empty plate. config: intrinsics, depth range, depth noise.
    plate_radius, plate_thickness: the plate (radius 0 = no plate).
    pose_source: returns the true ``T_table_camera`` at capture time (the cell wires it
    to the arm and turntable). seed: seeds the depth noise.
    """

    def __init__(
        self,
        mesh: trimesh.Trimesh | None,
        config: CameraConfig | None = None,
        *,
        plate_radius: float = 0.2,
        plate_thickness: float = 0.02,
        pose_source: Callable[[], Pose] | None = None,
        seed: int = 0,
    ) -> None:
        import open3d as o3d

        self.config = config if config is not None else CameraConfig()
        self._intrinsics = self.config.intrinsics
        self.pose_source = pose_source
        self.fail_next: Exception | None = None
        self.captures = 0
        self._rng = np.random.default_rng(seed)
        self._scene = o3d.t.geometry.RaycastingScene()
        parts: list[trimesh.Trimesh] = []
        if mesh is not None:
            if len(mesh.faces) == 0:
                raise ValueError("mesh: empty mesh (no faces)")
            parts.append(mesh)
        if plate_radius > 0:
            if not plate_thickness > 0:
                raise ValueError(f"plate_thickness: must be > 0, got {plate_thickness!r}")
            parts.append(plate_mesh(plate_radius, plate_thickness))
        self.mesh = mesh
        self._buffers: list[np.ndarray] = []  # from_numpy shares memory: keep the arrays alive with the scene
        for part in parts:
            vertices = np.ascontiguousarray(part.vertices, dtype=np.float32)
            faces = np.ascontiguousarray(part.faces, dtype=np.uint32)
            self._buffers += [vertices, faces]
            self._scene.add_triangles(o3d.core.Tensor.from_numpy(vertices), o3d.core.Tensor.from_numpy(faces))
        k = self._intrinsics
        v, u = np.mgrid[0 : k.height, 0 : k.width].astype(np.float64)
        # Camera-frame ray directions ((u - cx) / fx, (v - cy) / fy, 1), (H*W,) each: with z = 1,
        # t_hit is planar z-depth.
        self._dir_x = ((u - k.cx) / k.fx).astype(np.float32).ravel()
        self._dir_y = ((v - k.cy) / k.fy).astype(np.float32).ravel()

    @property
    def intrinsics(self) -> Intrinsics:
        return self._intrinsics

    def render(self, T_table_camera: Pose) -> NDArray[np.float32]:
        """(H, W) float32 noise-free planar z-depth from ``T_table_camera``; 0 outside [min_depth, max_depth]."""
        import open3d as o3d

        k = self._intrinsics
        rays = np.empty((k.height * k.width, 6), dtype=np.float32)
        rays[:, :3] = T_table_camera.translation.astype(np.float32)
        R = T_table_camera.rotation.astype(np.float32)
        for i in range(3):  # R @ (x, y, 1) elementwise: no BLAS threads competing with open3d's
            rays[:, 3 + i] = self._dir_x * R[i, 0] + self._dir_y * R[i, 1] + R[i, 2]
        hits = self._scene.cast_rays(o3d.core.Tensor.from_numpy(rays.reshape(k.height, k.width, 6)))
        depth = hits["t_hit"].numpy()
        return self._cut(depth)

    def _cut(self, depth: NDArray[np.float32]) -> NDArray[np.float32]:
        in_range = np.isfinite(depth) & (depth >= self.config.min_depth) & (depth <= self.config.max_depth)
        return np.where(in_range, depth, np.float32(0.0)).astype(np.float32)

    def device_state(self) -> dict[str, Any]:
        """The depth-noise RNG state (JSON-ready), for a resumed session to continue exactly."""
        return {"depth_noise": self._rng.bit_generator.state}

    def restore_device_state(self, state: dict[str, Any]) -> None:
        self._rng.bit_generator.state = state["depth_noise"]

    def capture(self) -> DepthFrame:
        """Render from ``pose_source()``, add the configured depth noise; ``T_world_camera`` is the true pose."""
        if self.fail_next is not None:
            exc, self.fail_next = self.fail_next, None
            raise exc
        if self.pose_source is None:
            raise CaptureError("simulated camera: no pose source (it is not mounted in a cell)")
        pose = self.pose_source()
        depth = self.render(pose)
        if self.config.depth_noise_std > 0:
            valid = depth > 0
            noise = self._rng.normal(0.0, self.config.depth_noise_std, int(valid.sum())).astype(np.float32)
            depth[valid] += noise
            depth = self._cut(depth)
        self.captures += 1
        return DepthFrame(depth, pose, self._intrinsics)


class SimulatedArm:
    """An arm that puts the camera exactly where it is told (reach is checked by the cell).

    initial: the starting ``T_base_camera``. ``moves`` counts successful moves.
    """

    def __init__(self, initial: Pose | None = None) -> None:
        self._pose = initial if initial is not None else Pose.identity()
        self.fail_next: Exception | None = None
        self.moves = 0

    @property
    def pose(self) -> Pose:
        return self._pose

    def move_to(self, T_base_camera: Pose) -> None:
        if not isinstance(T_base_camera, Pose):
            raise ValueError(f"T_base_camera: expected a Pose, got {type(T_base_camera).__name__}")
        if self.fail_next is not None:
            exc, self.fail_next = self.fail_next, None
            raise exc
        self._pose = T_base_camera
        self.moves += 1


class SimulatedTurntable:
    """A turntable that turns instantly; ``angle`` is kept wrapped to (-pi, pi]."""

    def __init__(self, angle: float = 0.0) -> None:
        self._angle = wrap_angle(angle)
        self.fail_next: Exception | None = None
        self.rotations = 0

    @property
    def angle(self) -> float:
        return self._angle

    def reset(self, angle: float) -> None:
        """Put the plate at ``angle`` without a rotation (start-up, or a resumed session)."""
        if not isinstance(angle, int | float) or not math.isfinite(angle):
            raise ValueError(f"angle: must be a finite number (radians), got {angle!r}")
        self._angle = wrap_angle(float(angle))

    def rotate_to(self, angle: float) -> None:
        if not isinstance(angle, int | float) or not math.isfinite(angle):
            raise ValueError(f"angle: must be a finite number (radians), got {angle!r}")
        if self.fail_next is not None:
            exc, self.fail_next = self.fail_next, None
            raise exc
        self._angle = wrap_angle(float(angle))
        self.rotations += 1


def make_sim_cell(
    mesh: trimesh.Trimesh | None,
    camera_config: CameraConfig | None = None,
    cell_config: CellConfig | None = None,
    seed: int = 0,
) -> Cell:
    """A cell of simulated devices scanning ``mesh`` (table frame, e.g. from ``load_mesh``).

    ``cell_config.kinematics`` 'urdf' (default) builds the arm model of ``cell_config.arm`` (the UR5) and a
    :class:`SimulatedJointArm`; 'reach_sphere' a :class:`SimulatedArm`. The camera starts at the cell's
    initial view (turntable at the angle that view needs; the URDF arm at its IK solution nearest its home).
    The camera's pose source is ``Rz(-theta) @ T_base_camera`` (forward kinematics of the arm's joints for
    a URDF arm): the true camera pose in the table frame.
    ``seed`` seeds the depth noise and (independently) the pose noise.
    ValueError naming the field for a bad arm (unloadable URDF, missing flange frame, ...).
    """
    camera_config = camera_config if camera_config is not None else CameraConfig()
    cell_config = cell_config if cell_config is not None else CellConfig()
    depth_seed, pose_seed = np.random.SeedSequence(seed).spawn(2)
    turntable = SimulatedTurntable()
    kinematics = None
    arm: SimulatedArm | SimulatedJointArm
    if cell_config.kinematics == "urdf":
        from devices.arm.kinematics import ArmKinematics

        kinematics = ArmKinematics(cell_config.arm, cell_config.plate_radius, cell_config.plate_thickness)
        joint_arm = SimulatedJointArm(kinematics.joint_names, kinematics.home, pose_of=kinematics.camera_pose)
        arm = joint_arm

        def pose_source() -> Pose:
            assert kinematics is not None
            return rz(-turntable.angle) @ kinematics.camera_pose(joint_arm.joint_positions())
    else:
        sphere_arm = SimulatedArm()
        arm = sphere_arm

        def pose_source() -> Pose:
            return rz(-turntable.angle) @ sphere_arm.pose

    camera = SimulatedCamera(
        mesh,
        camera_config,
        plate_radius=cell_config.plate_radius,
        plate_thickness=cell_config.plate_thickness,
        pose_source=pose_source,
        seed=int(depth_seed.generate_state(1)[0]),
    )
    cell = Cell(
        camera,
        arm,
        turntable,
        cell_config,
        kinematics=kinematics,
        pose_noise_translation=camera_config.pose_noise_translation,
        pose_noise_rotation_deg=camera_config.pose_noise_rotation_deg,
        seed=int(pose_seed.generate_state(1)[0]),
    )
    try:
        motion = cell.plan_motion(cell.initial_pose())
    except DeviceError:
        return cell  # an unusual geometry: leave the arm where it is until the first move
    turntable.rotate_to(motion.angle)
    if isinstance(arm, SimulatedJointArm):
        assert motion.q is not None
        arm.reset(motion.q)
    else:
        arm.move_to(motion.T_base_camera)
    arm.moves = turntable.rotations = 0
    return cell


def sim_cell_from_config(config: DeviceConfig) -> tuple[str, trimesh.Trimesh, Cell]:
    """(object name, placed mesh, simulated cell) for ``config``: resolves ``config.model`` and builds the cell."""
    from devices.builtins import resolve_model

    name, mesh = resolve_model(config.model, up=config.up, size=config.size)
    return name, mesh, make_sim_cell(mesh, config.camera, config.cell, seed=config.seed)
