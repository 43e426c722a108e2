"""Where the arm can put the camera: plate angle + IK + joint limits + collisions, per view, with its reason.

A view ``T_table_camera`` (the planner's world is the table frame) is reached by turning the plate to some angle
theta and moving the arm so that ``T_base_camera = Rz(theta) @ T_table_camera``. The plate angles tried put the
view's azimuth at the arm's azimuth plus each of ``ArmConfig.plate_offsets_deg``. A view is *reachable* when
one of them has an IK solution inside the joint limits, free of collisions; otherwise the reason of the attempt
that got furthest is kept: ``no_ik`` < ``joint_limit`` < ``collision:<link>:<obstacle>``.

Speed (400 candidates per plan): with the object near the turntable axis, every candidate of one parallel
maps to almost the same ``T_base_camera``, so IK solutions are cached by that pose (quantised); the last
solution seeds the next IK (the planner asks candidate after candidate along the parallels), and a library
of configurations sampled at start-up gives seeds near any pose. Collisions are always checked (the object
box and the plate angle change).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray
from scipy.spatial import KDTree

from devices.arm.collision import CollisionWorld
from devices.arm.ik import fixed_seeds, solve_ik
from devices.arm.model import ArmModel
from planner.types import Pose

LIBRARY_SIZE = 600
"""Configurations sampled at start-up whose camera poses seed IK for nearby targets."""
ORIENTATION_WEIGHT = 0.2
"""Metres per unit of camera-axis difference in the seed library's pose distance."""
FAILURE_RADIUS = 0.005
"""A pose within this distance (metres, in the seed library's pose metric) of one whose IK failed fails too."""
CACHE_SIZE = 20_000
"""IK results kept (cleared when full)."""


def rz_matrix(theta: float) -> NDArray[np.float64]:
    c, s = math.cos(theta), math.sin(theta)
    return np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])


def wrap(angle: float) -> float:
    """``angle`` wrapped to (-pi, pi]."""
    a = math.remainder(angle, 2 * math.pi)
    return math.pi if a == -math.pi else a


@dataclass(frozen=True, eq=False)
class ArmTarget:
    """A reachable view: plate ``angle`` (rad, (-pi, pi]), joint target ``q`` (n,) and ``T_base_camera`` (FK of q).

    move_estimate: seconds the move from the current state would take at the speed limits (turntable, then arm).
    """

    angle: float
    q: NDArray[np.float64]
    T_base_camera: Pose
    move_estimate: float


def _severity(reason: str) -> int:
    return 2 if reason.startswith("collision") else 1 if reason == "joint_limit" else 0


class ArmReach:
    """Reachability and targets of views for one arm in one cell (not thread-safe: one per cell).

    arm: the loaded model. world: its collision world (plate, table, object box).
    """

    def __init__(self, arm: ArmModel, world: CollisionWorld) -> None:
        self.arm = arm
        self.world = world
        self._data = arm.model.createData()
        mount = arm.T_base_mount.translation
        self.arm_azimuth = math.atan2(mount[1], mount[0])
        self._offsets = [math.radians(o) for o in arm.config.plate_offsets_deg]
        self._library = [q for q in fixed_seeds(arm, LIBRARY_SIZE, seed=1) if world.collision(q, 0.0) is None]
        self._library_tree = KDTree(np.array([self._feature(arm.camera_pose(q, self._data)) for q in self._library]))
        self._wrist_joint = int(arm.model.frames[arm.camera_frame].parentJoint)
        self._wrist_in_camera, self._root, self.reach = self._reach_bound()
        self._cache: dict[tuple[int, ...], tuple[list[NDArray[np.float64]], str | None]] = {}
        self._last: NDArray[np.float64] | None = None
        self._last_offset = 0
        self._failed: list[NDArray[np.float64]] = []

    # ------------------------------------------------------------------ helpers

    def _reach_bound(self) -> tuple[NDArray[np.float64], NDArray[np.float64], float]:
        """(the last joint's origin in the camera frame (3,), the first joint's origin (3,), the largest distance
        between the two over the seed library and the zero configuration, plus 2 %): a pose whose last joint would
        be farther than that from the first is out of reach (``no_ik`` without running IK)."""
        import pinocchio as pin  # pyright: ignore[reportMissingImports]  (under cmeel.prefix)

        model, data = self.arm.model, self._data
        distances = []
        wrist_in_camera = np.zeros(3)
        root = np.zeros(3)
        for q in [np.zeros(self.arm.nq), *self._library]:
            pin.framesForwardKinematics(model, data, q)
            wrist, root = np.array(data.oMi[self._wrist_joint].translation), np.array(data.oMi[1].translation)
            distances.append(float(np.linalg.norm(wrist - root)))
            wrist_in_camera = np.array(data.oMf[self.arm.camera_frame].actInv(data.oMi[self._wrist_joint]).translation)
        return wrist_in_camera, root, 1.02 * max(distances)

    def out_of_reach(self, T_base_camera: Pose) -> bool:
        """Whether the last joint would be beyond :attr:`reach` from the first for this camera pose."""
        wrist = T_base_camera.rotation @ self._wrist_in_camera + T_base_camera.translation
        return bool(np.linalg.norm(wrist - self._root) > self.reach)

    @staticmethod
    def _feature(T: Pose) -> NDArray[np.float64]:
        R = T.rotation
        return np.concatenate([T.translation, ORIENTATION_WEIGHT * R[:, 2], ORIENTATION_WEIGHT * R[:, 0]])

    def plate_angles(self, T_table_camera: Pose, current_angle: float) -> list[float]:
        """The plate angles tried for this view (rad), in the order of ``plate_offsets_deg``."""
        x, y = T_table_camera.translation[:2]
        if math.hypot(x, y) < 1e-9:
            return [wrap(current_angle + o) for o in self._offsets]
        return [wrap(self.arm_azimuth + o - math.atan2(y, x)) for o in self._offsets]

    def move_estimate(
        self, q_from: NDArray[np.float64], q_to: NDArray[np.float64], angle_from: float, angle_to: float
    ) -> float:
        """Seconds of a rest-to-rest move: turntable at its speed, then the slowest joint (trapezoid profile)."""
        turn = abs(wrap(angle_to - angle_from)) / math.radians(self.arm.config.turntable_speed_deg)
        dq = np.abs(np.asarray(q_to) - np.asarray(q_from))
        v, a = self.arm.velocity, self.arm.acceleration
        t = np.where(dq > v * v / a, dq / v + v / a, 2.0 * np.sqrt(dq / a))
        return float(turn + (np.max(t) if len(t) else 0.0))

    def _ik(
        self, T_base_camera: Pose, reference: NDArray[np.float64], *, first: bool
    ) -> tuple[list[NDArray[np.float64]], str | None]:
        key = (
            *np.round(T_base_camera.translation * 2000).astype(int),  # 0.5 mm
            *np.round(T_base_camera.rotation[:, :2].ravel() * 1000).astype(int),  # ~1 mrad
            int(first),
        )
        hit = self._cache.get(key)
        if hit is not None:
            return hit
        feature = self._feature(T_base_camera)
        if self._failed and float(np.min(np.linalg.norm(np.array(self._failed) - feature, axis=1))) < FAILURE_RADIUS:
            return [], "no_ik"
        seeds: list[NDArray[np.float64]] = []
        if self._last is not None:
            seeds.append(self._last)
        seeds.append(reference)
        k = self.arm.config.ik_seeds if first else 2 * self.arm.config.ik_seeds
        _, idx = self._library_tree.query(feature, k=min(k, len(self._library)))
        seeds += [self._library[i] for i in np.atleast_1d(idx)]
        result = solve_ik(self.arm, T_base_camera, seeds, reference, self._data, first=first)
        if len(self._cache) >= CACHE_SIZE:
            self._cache.clear()
        self._cache[key] = result
        if result[0]:
            self._last = result[0][0]
        elif result[1] == "no_ik":
            self._failed = [*self._failed[-(CACHE_SIZE // 100) :], feature]
        return result

    # ------------------------------------------------------------------ queries

    def reachability(
        self, T_table_camera: Pose, q_current: NDArray[np.float64], angle_current: float
    ) -> tuple[ArmTarget | None, str | None]:
        """A plate angle whose IK solution is inside the limits and free (the first found; the offset that
        served the previous query is tried first), or (None, reason)."""
        worst = "no_ik"
        angles = self.plate_angles(T_table_camera, angle_current)
        order = [self._last_offset, *(i for i in range(len(angles)) if i != self._last_offset)]
        for i in order:  # the offset that served the previous view first: neighbours behave alike
            target, reason = self._try(T_table_camera, angles[i], q_current, angle_current, first=True)
            if target is not None:
                self._last_offset = i
                return target, None
            assert reason is not None
            if _severity(reason) > _severity(worst):
                worst = reason
        return None, worst

    def best_target(
        self, T_table_camera: Pose, q_current: NDArray[np.float64], angle_current: float
    ) -> tuple[ArmTarget | None, str | None]:
        """Among every plate angle and IK branch, the free target with the shortest estimated move."""
        best: ArmTarget | None = None
        worst = "no_ik"
        for angle in self.plate_angles(T_table_camera, angle_current):
            target, reason = self._try(T_table_camera, angle, q_current, angle_current, first=False)
            if target is None:
                assert reason is not None
                if _severity(reason) > _severity(worst):
                    worst = reason
            elif best is None or target.move_estimate < best.move_estimate:
                best = target
        return (best, None) if best is not None else (None, worst)

    def _try(
        self, T_table_camera: Pose, angle: float, q_current: NDArray[np.float64], angle_current: float, *, first: bool
    ) -> tuple[ArmTarget | None, str | None]:
        R = rz_matrix(angle)
        T_base_camera = Pose.trusted(R @ T_table_camera.rotation, R @ T_table_camera.translation)
        if self.out_of_reach(T_base_camera):
            return None, "no_ik"
        solutions, reason = self._ik(T_base_camera, q_current, first=first)
        if not solutions:
            return None, reason
        if first and self.world.collision(solutions[0], angle) is not None:
            solutions, _ = self._ik(T_base_camera, q_current, first=False)  # another branch may be free
        best: ArmTarget | None = None
        collision: str | None = None
        for q in solutions:
            hit = self.world.collision(q, angle)
            if hit is not None:
                collision = collision or hit
                continue
            estimate = self.move_estimate(q_current, q, angle_current, angle)
            if best is None or estimate < best.move_estimate:
                best = ArmTarget(angle, q, self.arm.camera_pose(q, self._data), estimate)
            if first:
                break
        return (best, None) if best is not None else (None, collision)
