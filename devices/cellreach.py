"""How a cell's arm reaches a view: the reach sphere or a URDF arm, two implementations of one :class:`Reach`.

A :class:`devices.cell.Cell` holds one (``Cell.reach``) and asks it every question whose answer depends on the
kind of arm: where the camera is, whether a view is reachable and why not, the motion to a view, how long moves
take, the arm's state for a resume. Frames as in devices/cell.py (``T_base_camera = Rz(theta) @ T_table_camera``).

- :class:`SphereReach` (``CellConfig.kinematics = "reach_sphere"``): an :class:`devices.protocols.Arm` that goes
  to a camera pose; the plate turns the camera's azimuth onto the arm base's azimuth and the camera must be
  within the reach sphere. Kept for comparison.
- :class:`UrdfArm` (``"urdf"``): a robot model (:class:`devices.arm.kinematics.ArmKinematics`) and a
  :class:`devices.protocols.JointArm`. A view is reachable when some plate angle gives an IK solution inside the
  joint limits and free of collisions; a move takes the one with the shortest move and a collision-free joint
  trajectory.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from typing import TYPE_CHECKING, Any, Protocol

import numpy as np
from numpy.typing import NDArray

from devices.angles import wrap_angle
from devices.config import CellConfig
from devices.motion import SPHERE_CAMERA_SPEED, Motion, rz
from devices.protocols import Arm, JointArm, Turntable, UnreachableError
from planner.types import BoundingBox, CameraPath, Pose

if TYPE_CHECKING:
    from devices.arm.kinematics import ArmKinematics

STALE_JOINTS = 1e-3
"""A prepared motion whose start is farther than this from the arm's joints (radians, any joint) is stale."""


def trapezoid_fraction(t: float, distance: float, velocity: float, acceleration: float) -> float:
    """The fraction (0..1) of ``distance`` a rest-to-rest trapezoid (triangle when short) at ``velocity`` and
    ``acceleration`` has covered ``t`` seconds after it started (0 before it starts, 1 after it ends)."""
    if t <= 0.0 or distance <= 0.0:
        return 0.0 if distance > 0.0 else 1.0
    if distance > velocity * velocity / acceleration:
        ramp = velocity / acceleration
        total = distance / velocity + ramp
        if t >= total:
            return 1.0
        if t < ramp:
            done = 0.5 * acceleration * t * t
        elif t <= total - ramp:
            done = 0.5 * velocity * ramp + velocity * (t - ramp)
        else:
            done = distance - 0.5 * acceleration * (total - t) ** 2
    else:
        total = 2.0 * math.sqrt(distance / acceleration)
        if t >= total:
            return 1.0
        half = total / 2.0
        done = 0.5 * acceleration * t * t if t <= half else distance - 0.5 * acceleration * (total - t) ** 2
    return min(1.0, max(0.0, done / distance))


class Reach(Protocol):
    """The arm-dependent half of a cell: reachability, motion planning and move times from the current state."""

    def camera_pose(self) -> Pose:
        """``T_base_camera`` of the camera now (noise-free)."""
        ...

    def joint_positions(self) -> NDArray[np.float64] | None:
        """(n,) the arm's joints, radians; None for an arm without joints (the reach sphere)."""
        ...

    def set_object_box(self, bbox: BoundingBox | None) -> None:
        """The object's box (table frame) the arm keeps clear of; None = none. No effect where there is no
        collision model."""
        ...

    def set_config(self, config: CellConfig) -> None:
        """The cell's geometry changed (``Cell.config`` set): answer from ``config`` from now on."""
        ...

    def plan(self, T_table_camera: Pose, plate_angle: float | None, then: Sequence[Pose]) -> Motion:
        """The motion that puts the camera at ``T_table_camera`` (see :meth:`devices.cell.Cell.plan_motion`)."""
        ...

    def is_current(self, motion: Motion) -> bool:
        """Whether ``motion`` still starts where the arm is (a motion planned before the arm moved is not)."""
        ...

    def reachability(self, T_table_camera: Pose) -> tuple[bool, str | None]:
        """(reachable, reason) of one view."""
        ...

    def reachability_many(self, poses: Sequence[Pose]) -> list[tuple[bool, str | None]]:
        """:meth:`reachability` of many views, in their order."""
        ...

    def is_reachable(self, T_table_camera: Pose) -> bool:
        """``reachability(T)[0]``, as cheaply as the arm allows."""
        ...

    def move_estimate(self, T_table_camera: Pose) -> float:
        """Seconds of the move to a view from now (inf if unreachable)."""
        ...

    def move_times(self, poses: Sequence[Pose], exact: bool) -> tuple[NDArray[np.float64], NDArray[np.bool_]]:
        """((K + 1, K + 1) seconds between the current state and the K views, (K + 1,) which of them are
        reachable; entry 0 the current state). The cell sets the unreachable rows and columns to inf."""
        ...

    def move_paths(self, poses: Sequence[Pose], hz: float) -> list[CameraPath | None]:
        """Per view, the camera's path on the move from now to it, frames at ``hz`` (None: unreachable): a planning
        estimate, no motion planned (:meth:`devices.cell.Cell.move_paths`)."""
        ...

    def arm_state(self) -> dict[str, Any] | None:
        """What a resume needs to move on from the same arm configuration (JSON-ready); None: nothing."""
        ...

    def restore_arm(self, state: dict[str, Any]) -> None:
        """Put a simulated arm and turntable back at :meth:`arm_state`'s ``state`` (a real one stays where it is)."""
        ...


class SphereReach:
    """The reach sphere: an arm that goes to a camera pose within ``arm_min_reach`` .. ``arm_reach`` of the arm base.

    arm, turntable: the cell's devices (None in a device-less planning cell, which then answers reachability
    only: it knows no camera pose to move from)."""

    def __init__(self, config: CellConfig, arm: Arm | None, turntable: Turntable | None) -> None:
        self.arm = arm
        self.turntable = turntable
        self.set_config(config)

    def set_config(self, config: CellConfig) -> None:
        """The reach, the heights and the arm base of ``config`` from now on."""
        self.config = config
        self._arm_base = np.asarray(config.arm_base, dtype=np.float64)

    def _angle(self) -> float:
        assert self.turntable is not None, "a device-less cell knows no plate angle"
        return self.turntable.angle

    def _arm_pose(self) -> Pose:
        assert self.arm is not None, "a device-less cell knows no camera pose"
        return self.arm.pose

    def camera_pose(self) -> Pose:
        return self._arm_pose()

    def joint_positions(self) -> NDArray[np.float64] | None:
        return None

    def set_object_box(self, bbox: BoundingBox | None) -> None:
        """No collision model: nothing to do."""

    def plan(self, T_table_camera: Pose, plate_angle: float | None, then: Sequence[Pose]) -> Motion:
        """theta turns the camera's azimuth onto the arm base's azimuth (``plate_angle`` when given; a camera on the
        turntable axis keeps the current angle). UnreachableError (with the numbers) when the camera would be below
        ``min_height`` above the plate top, or farther than ``arm_reach`` / nearer than ``arm_min_reach`` from the
        arm base. ``then`` is ignored."""
        x, y, z = T_table_camera.translation
        cfg = self.config
        if z < cfg.min_height:
            raise UnreachableError(
                f"unreachable: camera at height {z:.3f} m is below the plate top + clearance ({cfg.min_height:.3f} m)"
            )
        if plate_angle is not None:
            theta = wrap_angle(plate_angle)
        elif math.hypot(x, y) < 1e-9:
            theta = wrap_angle(self._angle())
        else:
            arm_azimuth = math.atan2(self._arm_base[1], self._arm_base[0])
            theta = wrap_angle(arm_azimuth - math.atan2(y, x))
        T_base_camera = rz(theta) @ T_table_camera
        distance = float(np.linalg.norm(T_base_camera.translation - self._arm_base))
        if distance > cfg.arm_reach:
            raise UnreachableError(
                f"unreachable: camera {distance:.3f} m from the arm base, beyond arm_reach {cfg.arm_reach:.3f} m"
            )
        if distance < cfg.arm_min_reach:
            raise UnreachableError(
                f"unreachable: camera {distance:.3f} m from the arm base, "
                f"nearer than arm_min_reach {cfg.arm_min_reach:.3f} m"
            )
        turn = abs(wrap_angle(theta - self._angle())) / math.radians(cfg.arm.turntable_speed_deg)
        travel = float(np.linalg.norm(T_base_camera.translation - self._arm_pose().translation))
        return Motion(theta, T_base_camera, duration=turn + travel / SPHERE_CAMERA_SPEED)

    def is_current(self, motion: Motion) -> bool:
        """The arm goes to the camera pose from wherever it is: a planned motion stays valid."""
        return True

    def reachability(self, T_table_camera: Pose) -> tuple[bool, str | None]:
        ok = self.is_reachable(T_table_camera)
        return ok, None if ok else "reach"

    def reachability_many(self, poses: Sequence[Pose]) -> list[tuple[bool, str | None]]:
        return [self.reachability(T) for T in poses]

    def is_reachable(self, T_table_camera: Pose) -> bool:
        """In closed form, no Pose built: the plate turns the camera onto the arm base's azimuth, so its distance to
        the base is that of two points in one vertical half-plane."""
        x, y, z = T_table_camera.translation
        cfg = self.config
        if z < cfg.min_height:
            return False
        base_radial = math.hypot(self._arm_base[0], self._arm_base[1])
        distance = math.hypot(math.hypot(x, y) - base_radial, z - self._arm_base[2])
        return cfg.arm_min_reach <= distance <= cfg.arm_reach

    def move_estimate(self, T_table_camera: Pose) -> float:
        """The plate turn plus the camera's straight travel at ``SPHERE_CAMERA_SPEED``."""
        try:
            return self.plan(T_table_camera, None, ()).duration
        except UnreachableError:
            return math.inf

    def move_times(self, poses: Sequence[Pose], exact: bool) -> tuple[NDArray[np.float64], NDArray[np.bool_]]:
        """Plate turn + the camera's straight travel at ``SPHERE_CAMERA_SPEED`` (``exact`` changes nothing)."""
        from devices.arm.reach import turn_matrix

        ok = np.ones(len(poses) + 1, dtype=bool)
        xyz, angles = [self._arm_pose().translation], [self._angle()]
        for k, T in enumerate(poses, start=1):
            try:
                motion = self.plan(T, None, ())
            except UnreachableError:
                ok[k] = False
                xyz.append(xyz[0])
                angles.append(angles[0])
                continue
            xyz.append(motion.T_base_camera.translation)
            angles.append(motion.angle)
        turn = turn_matrix(np.array(angles))
        p = np.stack(xyz)
        travel = np.linalg.norm(p[:, None, :] - p[None, :, :], axis=2)
        times = turn / math.radians(self.config.arm.turntable_speed_deg) + travel / SPHERE_CAMERA_SPEED
        return times, ok

    def move_paths(self, poses: Sequence[Pose], hz: float) -> list[CameraPath | None]:
        """The moves as the reach sphere makes them (:meth:`plan`: the plate's turn, then the camera's straight
        travel), sampled at the frames' times (``devices.move_capture.capture_times``): exact, not an estimate."""
        from devices.move_capture import MovePath, capture_times

        out: list[CameraPath | None] = []
        start = self._arm_pose()
        angle = self._angle()
        speed = math.radians(self.config.arm.turntable_speed_deg)
        for T in poses:
            try:
                motion = self.plan(T, None, ())
            except UnreachableError:
                out.append(None)
                continue
            path = MovePath(motion, angle, start, None, speed)
            times = capture_times(path.duration, hz)
            out.append(CameraPath.of_poses(path.duration, times, path.poses(times)))
        return out

    def arm_state(self) -> dict[str, Any] | None:
        return None

    def restore_arm(self, state: dict[str, Any]) -> None:
        """Nothing to restore: the reach sphere moves straight to each view."""


class UrdfArm:
    """A robot model and the :class:`devices.protocols.JointArm` it plans for: IK, collisions, joint trajectories."""

    def __init__(self, kinematics: ArmKinematics, arm: JointArm, turntable: Turntable) -> None:
        self.kinematics = kinematics
        self.arm = arm
        self.turntable = turntable
        self._fk_data: Any = None  # pinocchio's buffers of the path estimate's forward kinematics, made on first use

    def set_config(self, config: CellConfig) -> None:
        """Nothing to change: the arm model keeps the geometry it was built with (``ArmKinematics``)."""

    def _state(self) -> tuple[NDArray[np.float64], float]:
        return np.asarray(self.arm.joint_positions(), dtype=np.float64), self.turntable.angle

    def camera_pose(self) -> Pose:
        """Forward kinematics of the arm's reported joints."""
        return self.kinematics.camera_pose(self.arm.joint_positions())

    def joint_positions(self) -> NDArray[np.float64] | None:
        return self.arm.joint_positions()

    def set_object_box(self, bbox: BoundingBox | None) -> None:
        """The box the arm keeps clear of, padded by ``arm.object_padding``."""
        if bbox is None:
            self.kinematics.set_object_box(None, None)
        else:
            self.kinematics.set_object_box(bbox.lower, bbox.upper)

    def plan(self, T_table_camera: Pose, plate_angle: float | None, then: Sequence[Pose]) -> Motion:
        """The reachable, collision-free plate angle and IK solution with the shortest move (with ``then``: the
        move plus the quickest move on, :meth:`ArmReach.best_target`), and its timed trajectory
        (:meth:`ArmKinematics.plan`); UnreachableError with ``reason`` otherwise."""
        move = self.kinematics.plan(T_table_camera, self.arm.joint_positions(), self.turntable.angle, plate_angle, then)
        t = move.target
        return Motion(
            t.angle,
            t.T_base_camera,
            t.q,
            move.trajectory,
            move.duration,
            move.path_method,
            move.planning_seconds,
            move.retract,
            move.overlapped,
        )

    def is_current(self, motion: Motion) -> bool:
        """The motion's first trajectory (the retract, else the move) starts within ``STALE_JOINTS`` of the arm's
        joints."""
        first = motion.retract if motion.retract is not None else motion.trajectory
        if first is None:
            return True
        q, _ = self._state()
        return bool(np.max(np.abs(first.positions[0] - q)) <= STALE_JOINTS)

    def reachability(self, T_table_camera: Pose) -> tuple[bool, str | None]:
        """IK + joint limits + collisions at some plate angle (reason ``no_ik``, ``joint_limit`` or
        ``collision:<link>:<obstacle>``); the path itself is planned only on a move (``no_path`` then)."""
        q, angle = self._state()
        return self.kinematics.reachability(T_table_camera, q, angle)

    def reachability_many(self, poses: Sequence[Pose]) -> list[tuple[bool, str | None]]:
        """In their order: neighbours warm-start each other's IK."""
        q, angle = self.arm.joint_positions(), self.turntable.angle
        return [self.kinematics.reachability(T, q, angle) for T in poses]

    def is_reachable(self, T_table_camera: Pose) -> bool:
        return self.reachability(T_table_camera)[0]

    def move_estimate(self, T_table_camera: Pose) -> float:
        """Plate turn plus the slowest joint to the nearest target (every plate angle and IK branch; no path)."""
        target, _ = self.kinematics.reach.best_target(T_table_camera, self.arm.joint_positions(), self.turntable.angle)
        return math.inf if target is None else target.move_estimate

    def move_times(self, poses: Sequence[Pose], exact: bool) -> tuple[NDArray[np.float64], NDArray[np.bool_]]:
        """Plate turn and the slowest joint's trapezoid (:meth:`ArmReach.move_seconds`) between the views' cached
        reachability targets at every plate angle (:meth:`_cached_move_times`); ``exact``: each view's target is
        the one a move from the current state would take (:meth:`ArmReach.best_target`)."""
        kinematics = self.kinematics
        reach = kinematics.reach
        ok = np.ones(len(poses) + 1, dtype=bool)
        q0, a0 = self._state()
        if not exact:
            return self._cached_move_times(poses, q0, a0, ok), ok

        def turn_check(a: float) -> str | None:
            return kinematics.turn_blocked(q0, a0, a)

        qs, angles = [q0], [a0]
        for k, T in enumerate(poses, start=1):
            best, _ = reach.best_target(T, q0, a0, turn_check)
            ok[k] = best is not None
            qs.append(q0 if best is None else best.q)
            angles.append(a0 if best is None else best.angle)
        return reach.seconds_between(np.stack(qs), np.array(angles), np.stack(qs), np.array(angles)), ok

    def _cached_move_times(
        self, poses: Sequence[Pose], q0: NDArray[np.float64], a0: float, ok: NDArray[np.bool_]
    ) -> NDArray[np.float64]:
        """:meth:`move_times` from the cached reachability targets (``ok`` (K + 1,) is set False for the views none
        of whose plate angles has a free target). Each view's entry target: of its free targets at every plate
        angle (:meth:`ArmReach.free_targets`), the one with the shortest move from the current state (q0 (n,),
        plate angle a0); the move from view i to view j: from i's entry target to the nearest of j's targets."""
        reach = self.kinematics.reach
        options = [reach.free_targets(T, q0, a0) for T in poses]
        owner = np.array([k for k, opts in enumerate(options, start=1) for _ in opts], dtype=np.int64)
        n = len(poses) + 1
        times = np.full((n, n), math.inf)
        if len(owner) == 0:
            ok[1:] = False
            return times
        q_all = np.stack([q for opts in options for q, _ in opts])  # (M, n) every view's free targets
        a_all = np.array([a for opts in options for _, a in opts])
        from_here = reach.seconds_between(q0[None, :], np.array([a0]), q_all, a_all)[0]  # (M,)
        entry_q, entry_a = [q0], [a0]
        for k in range(1, n):
            mine = np.flatnonzero(owner == k)
            ok[k] = len(mine) > 0
            best = int(mine[np.argmin(from_here[mine])]) if len(mine) else -1
            entry_q.append(q0 if best < 0 else q_all[best])
            entry_a.append(a0 if best < 0 else float(a_all[best]))
        legs = reach.seconds_between(np.stack(entry_q), np.array(entry_a), q_all, a_all)  # (K + 1, M)
        for k in range(1, n):
            mine = owner == k
            if np.any(mine):
                times[:, k] = legs[:, mine].min(axis=1)
        times[1:, 0] = reach.seconds_between(np.stack(entry_q[1:]), np.array(entry_a[1:]), q0[None, :], np.array([a0]))[
            :, 0
        ]
        return times

    def move_paths(self, poses: Sequence[Pose], hz: float) -> list[CameraPath | None]:
        """An estimate of each move as the cell would make it from the current state, without planning its path:
        the target a move would take (every plate angle and IK branch, :meth:`ArmReach.best_target`, as
        :meth:`move_times` with ``exact``: about 2.5 ms a view with the UR5's closed-form IK); a retract to home
        first when the turn would sweep the object into the standing arm (:meth:`ArmKinematics.turn_collision`);
        the plate's turn the short way at its speed, arm still; then a straight joint path, every joint on the
        slowest joint's trapezoid (as ruckig's phase-synchronised timing), or turn and path together when the cell
        overlaps them (:meth:`ArmReach.move_seconds`). The camera at each frame's time
        (``devices.move_capture.capture_times``) is ``Rz(-angle(t)) @ FK(q(t))``. Not modelled: a path around an
        obstacle (the move planned then goes another way, and takes longer)."""
        from devices.move_capture import capture_times

        kinematics = self.kinematics
        reach, model = kinematics.reach, kinematics.model
        if self._fk_data is None:
            self._fk_data = model.model.createData()
        q0, a0 = self._state()
        speed = math.radians(kinematics.config.turntable_speed_deg)
        v, acc = np.asarray(model.velocity, dtype=np.float64), np.asarray(model.acceleration, dtype=np.float64)

        def turn_check(a: float) -> str | None:
            return kinematics.turn_blocked(q0, a0, a)

        def joint_leg(q_from: NDArray[np.float64], q_to: NDArray[np.float64]) -> tuple[float, int]:
            """(seconds, the slowest joint) of a straight rest-to-rest joint move."""
            dq = np.abs(q_to - q_from)
            per_joint = np.where(dq > v * v / acc, dq / v + v / acc, 2.0 * np.sqrt(dq / acc))
            slowest = int(np.argmax(per_joint))
            return float(per_joint[slowest]), slowest

        def along(q_from: NDArray[np.float64], q_to: NDArray[np.float64], t: float, joint: int) -> NDArray[np.float64]:
            u = trapezoid_fraction(t, abs(float(q_to[joint] - q_from[joint])), float(v[joint]), float(acc[joint]))
            return q_from + u * (q_to - q_from)

        out: list[CameraPath | None] = []
        for T in poses:
            target, _ = reach.best_target(T, q0, a0, turn_check)
            if target is None:
                out.append(None)
                continue
            q1, a1 = target.q, target.angle
            turn = wrap_angle(a1 - a0)
            turn_s = abs(turn) / speed
            retract = turn != 0 and kinematics.turn_collision(q0, a0, turn) is not None
            start = kinematics.home if retract else q0
            retract_s, retract_joint = joint_leg(q0, start) if retract else (0.0, 0)
            arm_s, arm_joint = joint_leg(start, q1)
            overlapped = not retract and reach.move_seconds(start, q1, a0, a1) < turn_s + arm_s - 1e-9
            duration = retract_s + (max(turn_s, arm_s) if overlapped else turn_s + arm_s)
            arm_start = retract_s + (0.0 if overlapped else turn_s)
            times = capture_times(duration, hz)
            rotations = np.empty((len(times), 3, 3))
            translations = np.empty((len(times), 3))
            for k, t in enumerate(times):
                if t < retract_s:
                    q, angle = along(q0, start, t, retract_joint), a0
                else:
                    angle = a0 + turn * (min(1.0, (t - retract_s) / turn_s) if turn_s > 0 else 1.0)
                    q = along(start, q1, t - arm_start, arm_joint)
                T_base = model.camera_pose(q, self._fk_data)
                c, s = math.cos(angle), math.sin(angle)
                R = np.array([[c, s, 0.0], [-s, c, 0.0], [0.0, 0.0, 1.0]])  # Rz(-angle)
                rotations[k] = R @ T_base.rotation
                translations[k] = R @ T_base.translation
            out.append(CameraPath(duration, times, rotations, translations))
        return out

    def arm_state(self) -> dict[str, Any] | None:
        """The joints and the plate angle (a resumed session moves on from the same configuration, so it picks the
        same IK branches)."""
        return {"q": [float(v) for v in self.arm.joint_positions()], "angle": float(self.turntable.angle)}

    def restore_arm(self, state: dict[str, Any]) -> None:
        """A simulated arm and turntable (those with ``reset``) are put back; ValueError for malformed joints."""
        reset_arm, reset_table = getattr(self.arm, "reset", None), getattr(self.turntable, "reset", None)
        if not (callable(reset_arm) and callable(reset_table)):
            return
        q = np.array(state["q"], dtype=np.float64)
        if q.shape != (len(self.arm.joint_names),) or not np.all(np.isfinite(q)):
            raise ValueError(f"arm joints {state['q']!r}")
        reset_arm(q)
        reset_table(float(state["angle"]))
