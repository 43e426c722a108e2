"""Simulated devices: a ray-casting depth camera, an arm and a turntable that just keep their state.

The camera renders the object mesh and the turntable plate (a cylinder of
``plate_radius`` whose top is z = 0, so it hides the object's underside) in the
table frame with open3d's ``RaycastingScene``. Rays go through pixel centres at
integer pixel coordinates, the convention of ``DepthFrame.points_camera``; each
ray's direction has camera-frame z = 1, so the hit distance is the planar
z-depth directly. (``RaycastingScene.create_rays_pinhole`` also scales its rays
to z = 1, but puts pixel centres at u + 0.5, half a pixel off this convention,
so the rays are built here.)

A sensor model (``CameraConfig.sensor``, :mod:`devices.sensors`) other than 'ideal' renders with jittered rays
(lateral noise), reads the surface normals (grazing incidence), casts a second set of rays from the other imager or
the projector (occlusion by the second viewpoint) and applies the per-pixel effects (flying pixels, noise, holes,
quantisation, range). A calibration model (``CameraConfig.calibration``, :mod:`devices.calibration_error`) makes the
pose the camera renders from differ from the nominal kinematics the cell reports.

Fault injection: set ``fail_next`` on any simulated device to an exception; its
next action raises it (and clears it) without changing the state.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from typing import Any, cast

import numpy as np
import trimesh
from numpy.typing import NDArray

from devices.angles import wrap_angle
from devices.arm.sim_arm import SimulatedJointArm
from devices.calibration_error import CellErrors, calibration_named, configuration_key
from devices.cell import Cell, rz
from devices.config import CameraConfig, CellConfig, DeviceConfig
from devices.move_capture import SimulatedMoveCapture
from devices.planner_noise import cell_config_for
from devices.protocols import CaptureError, DeviceError
from devices.sensors import apply_effects, second_view_visible, sensor_named
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
        self.sensor = sensor_named(self.config.sensor)
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

    def _rays(self, T_table_camera: Pose, dir_x: NDArray[np.float32], dir_y: NDArray[np.float32]) -> np.ndarray:
        """(H*W, 6) float32 rays (origin, direction with camera-frame z = 1) in the table frame."""
        k = self._intrinsics
        rays = np.empty((k.height * k.width, 6), dtype=np.float32)
        rays[:, :3] = T_table_camera.translation.astype(np.float32)
        R = T_table_camera.rotation.astype(np.float32)
        for i in range(3):  # R @ (x, y, 1) elementwise: no BLAS threads competing with open3d's
            rays[:, 3 + i] = dir_x * R[i, 0] + dir_y * R[i, 1] + R[i, 2]
        return rays

    def render(self, T_table_camera: Pose) -> NDArray[np.float32]:
        """(H, W) float32 noise-free planar z-depth from ``T_table_camera``; 0 outside [min_depth, max_depth]."""
        import open3d as o3d

        k = self._intrinsics
        rays = self._rays(T_table_camera, self._dir_x, self._dir_y)
        hits = self._scene.cast_rays(o3d.core.Tensor.from_numpy(rays.reshape(k.height, k.width, 6)))
        depth = hits["t_hit"].numpy()
        return self._cut(depth)

    def render_sensor(self, T_table_camera: Pose) -> NDArray[np.float32]:
        """(H, W) float32 depth as ``self.sensor`` measures it from ``T_table_camera`` (draws from the camera's RNG):
        lateral ray jitter, grazing incidence, the second viewpoint's occlusion (at ``sensor.baseline`` along the
        camera's +x), then :func:`devices.sensors.apply_effects` with ``config.depth_noise_std`` added."""
        import open3d as o3d

        k, sensor = self._intrinsics, self.sensor
        dir_x, dir_y = self._dir_x, self._dir_y
        if sensor.lateral_px > 0:
            n = k.width * k.height
            dir_x = (dir_x + self._rng.normal(0.0, sensor.lateral_px, n) / k.fx).astype(np.float32)
            dir_y = (dir_y + self._rng.normal(0.0, sensor.lateral_px, n) / k.fy).astype(np.float32)
        rays = self._rays(T_table_camera, dir_x, dir_y)
        hits = self._scene.cast_rays(o3d.core.Tensor.from_numpy(rays))
        depth = self._cut(hits["t_hit"].numpy().reshape(k.height, k.width))
        normals = hits["primitive_normals"].numpy()
        dirs = rays[:, 3:]
        cos = np.abs(np.einsum("ij,ij->i", normals, dirs)) / np.linalg.norm(dirs, axis=1)
        if sensor.baseline > 0:
            flat = depth.reshape(-1)
            hit = np.flatnonzero(flat > 0)
            points = rays[hit, :3].astype(np.float64) + flat[hit, None].astype(np.float64) * dirs[hit].astype(
                np.float64
            )
            origin = T_table_camera.translation + sensor.baseline * T_table_camera.rotation[:, 0]
            flat[hit[~second_view_visible(self._scene, origin, points)]] = 0.0
        out = apply_effects(
            depth, cos.reshape(k.height, k.width).astype(np.float32), sensor, self.config.depth_noise_std, self._rng
        )
        return self._cut(out)

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
        if not self.sensor.is_ideal:
            self.captures += 1
            return DepthFrame(self.render_sensor(pose), pose, self._intrinsics)
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
        self.stops = 0

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

    def stop(self) -> None:
        """Stop a move (a simulated move is instant: nothing is moving). ``stops`` counts the calls."""
        self.stops += 1


class SimulatedTurntable:
    """A turntable that turns instantly; ``angle`` is kept wrapped to (-pi, pi]."""

    def __init__(self, angle: float = 0.0) -> None:
        self._angle = wrap_angle(angle)
        self.fail_next: Exception | None = None
        self.rotations = 0
        self.stops = 0

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

    def stop(self) -> None:
        """Stop a rotation (a simulated rotation is instant: nothing is turning). ``stops`` counts the calls."""
        self.stops += 1


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
    ``seed`` seeds the depth noise and (independently) the pose noise and the calibration error
    (``camera_config.calibration``; the drawn errors are ``cell.errors``, a :class:`CellErrors`: the camera renders
    from ``errors.true_T_table_camera(...)``, the cell reports the nominal kinematics).
    ValueError naming the field for a bad arm (unloadable URDF, missing flange frame, ...).
    """
    camera_config = camera_config if camera_config is not None else CameraConfig()
    cell_config = cell_config_for(cell_config if cell_config is not None else CellConfig(), camera_config)
    depth_seed, pose_seed, error_seed, move_seed = np.random.SeedSequence(seed).spawn(4)
    errors = CellErrors(calibration_named(camera_config.calibration), int(error_seed.generate_state(1)[0]))
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
            q = joint_arm.joint_positions()
            if errors.model.is_exact:
                return rz(-turntable.angle) @ kinematics.camera_pose(q)
            key = configuration_key(q, Pose.identity())
            return errors.true_T_table_camera(kinematics.camera_pose(q), turntable.angle, key)
    else:
        sphere_arm = SimulatedArm()
        arm = sphere_arm

        def pose_source() -> Pose:
            if errors.model.is_exact:
                return rz(-turntable.angle) @ sphere_arm.pose
            key = configuration_key(None, sphere_arm.pose)
            return errors.true_T_table_camera(sphere_arm.pose, turntable.angle, key)

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
    cell.errors = errors
    cell.move_capture = SimulatedMoveCapture(camera, errors, seed=int(move_seed.generate_state(1)[0]))
    initial = _initial_move(cell, cell_config)
    if initial is None:
        return cell  # an unusual geometry: leave the arm where it is until the first move
    angle, q, T_base_camera = initial
    turntable.rotate_to(angle)
    if isinstance(arm, SimulatedJointArm):
        assert q is not None
        arm.reset(q.copy())
    else:
        arm.move_to(T_base_camera)
    arm.moves = turntable.rotations = 0
    return cell


_InitialMove = tuple[float, NDArray[np.float64] | None, Pose]
_INITIAL_MOVES: dict[CellConfig, _InitialMove | None] = {}
"""The move to the first view of a new cell, per cell config (:func:`_initial_move`)."""
_UNKNOWN = object()
INITIAL_MOVES_KEPT = 64
"""Cell configs whose initial move is remembered (forgotten all at once when full)."""


def _initial_move(cell: Cell, cell_config: CellConfig) -> _InitialMove | None:
    """(plate angle, joints q (n,) or None for the reach sphere, T_base_camera) of the move to the initial view
    of ``cell``, new and built from ``cell_config``; None when there is none. A pure function of the config (a new
    cell's arm stands at home, its plate at 0, no object box yet), which every session's create asks again (IK of
    every plate angle and branch: 20-50 ms with the UR5), so the answer is kept per config for the process."""
    kept = _INITIAL_MOVES.get(cell_config, _UNKNOWN)  # one lookup: another thread may clear the dict meanwhile
    if kept is not _UNKNOWN:
        return cast("_InitialMove | None", kept)
    found: _InitialMove | None
    try:
        motion = cell.plan_motion(cell.initial_pose())
        found = (motion.angle, None if motion.q is None else motion.q.copy(), motion.T_base_camera)
    except DeviceError:
        found = None
    if len(_INITIAL_MOVES) >= INITIAL_MOVES_KEPT:
        _INITIAL_MOVES.clear()
    _INITIAL_MOVES[cell_config] = found
    return found


def sim_cell_from_config(config: DeviceConfig) -> tuple[str, trimesh.Trimesh, Cell]:
    """(object name, placed mesh, simulated cell) for ``config``: resolves ``config.model`` and builds the cell."""
    from devices.builtins import resolve_model

    name, mesh = resolve_model(config.model, up=config.up, size=config.size)
    return name, mesh, make_sim_cell(mesh, config.camera, config.cell, seed=config.seed)
