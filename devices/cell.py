"""The robot cell: a camera on an arm and an object on a turntable, seen from the planner's world.

Frames (all z-up, metres, radians):

- ``base``: the lab frame. Origin at the centre of the plate's top surface, z up.
  The arm base (shoulder) is at ``CellConfig.arm_base``; the arm moves the
  camera to ``T_base_camera``.
- ``table``: fixed to the plate, rotating with it. ``T_base_table = Rz(theta)``
  with theta the turntable angle. The planner's ``world`` is the table frame, so
  ``T_table_camera = Rz(-theta) @ T_base_camera``.
- camera: OpenCV axes (+z forward, +x right, +y down).

Two kinds of arm (``CellConfig.kinematics``):

- ``urdf`` (default): a robot model (:class:`devices.arm.kinematics.ArmKinematics`, the UR5 by default) and a
  :class:`devices.protocols.JointArm`. A view is reachable when some plate angle gives an IK solution inside
  the joint limits and free of collisions (plate, table, the object's box, the arm itself); the move takes the
  one with the shortest move, turns the plate, then runs a collision-free joint trajectory. The camera pose is
  the forward kinematics of the arm's reported joints.
- ``reach_sphere``: an :class:`devices.protocols.Arm` that goes to a camera pose; the plate turns the camera's
  azimuth onto the arm base's azimuth and the camera must be within the reach sphere. Kept for comparison.

In both, the arm moves the camera to ``T_base_camera = Rz(theta) @ T_table_camera``.
``devices.sim.make_sim_cell`` builds a Cell of simulated devices.
"""

from __future__ import annotations

import math
import threading
from collections.abc import Sequence
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any

import numpy as np
from numpy.typing import NDArray
from scipy.spatial.transform import Rotation

from devices.angles import wrap_angle
from devices.config import CellConfig
from devices.protocols import Arm, Camera, JointArm, Turntable, UnreachableError
from devices.trajectory import JointTrajectory
from planner.types import BoundingBox, DepthFrame, Intrinsics, Pose

if TYPE_CHECKING:
    from devices.arm.kinematics import ArmKinematics


SPHERE_CAMERA_SPEED = 0.25
"""Reach sphere: the camera's straight-line speed assumed for a move's duration estimate, m/s."""


def rz(theta: float) -> Pose:
    """``Rz(theta)``: rotation by ``theta`` radians about +z (counter-clockwise seen from above)."""
    c, s = math.cos(theta), math.sin(theta)
    return Pose(np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]]), np.zeros(3))


@dataclass(frozen=True, eq=False)
class Motion:
    """How the cell reaches a view: turntable ``angle`` (rad, in (-pi, pi]) and the arm's ``T_base_camera``.

    With a URDF arm also: ``q`` (n,) the joint target, ``trajectory`` the timed joint trajectory from the
    current configuration, ``duration`` seconds of the whole move (plate turn + trajectory; for the reach
    sphere: the plate turn plus the camera's straight travel at ``SPHERE_CAMERA_SPEED``), ``path_method``
    ('straight' or 'rrt_connect') and ``planning_seconds``.
    """

    angle: float
    T_base_camera: Pose
    q: np.ndarray | None = None
    trajectory: JointTrajectory | None = None
    duration: float = 0.0
    path_method: str = ""
    planning_seconds: float = 0.0
    retract: JointTrajectory | None = None
    """URDF arm: the trajectory to the retracted configuration that runs before the plate turns, when the turn
    would sweep the object's box into the standing arm (None: the arm stands still while the plate turns)."""
    overlapped: bool = False
    """URDF arm: the plate turns while the arm runs ``trajectory`` (``ArmConfig.turn_while_moving``, the whole path
    clear of the turning object); ``duration`` then counts the longer of the two, not their sum."""

    @property
    def path_length(self) -> float:
        """Length of the joint path, radians (0 without a trajectory)."""
        return self.trajectory.path_length() if self.trajectory is not None else 0.0

    def to_json(self) -> dict[str, Any]:
        """The metrics of a move: plate angle, joints, ``T_base_camera``, joint path length and duration."""
        return {
            "plate_angle": float(self.angle),
            "joints": None if self.q is None else [float(v) for v in self.q],
            "T_base_camera": self.T_base_camera.to_dict(),
            "path_length": self.path_length,
            "move_duration": float(self.duration),
            "path_method": self.path_method or None,
            "motion_planning_seconds": float(self.planning_seconds),
            "retracted": self.retract is not None,
            "turn_overlapped": self.overlapped,
        }


class Cell:
    """A camera, an arm and a turntable working together in the table frame.

    camera, arm, turntable: any objects satisfying the protocols in ``devices.protocols`` (the arm a
    ``JointArm`` when ``kinematics`` is given, else an ``Arm``).
    config: the cell geometry (arm base, reach, plate).
    kinematics: the arm model that plans the moves of a ``JointArm`` (None = the reach sphere of ``config``).
    pose_noise_translation: std of the error of the reported camera position, per axis, metres.
    pose_noise_rotation_deg: std of the error of the reported orientation, per rotation-vector component, degrees.
    seed: seeds the pose noise.
    """

    def __init__(
        self,
        camera: Camera,
        arm: Arm | JointArm,
        turntable: Turntable,
        config: CellConfig | None = None,
        *,
        kinematics: ArmKinematics | None = None,
        pose_noise_translation: float = 0.0,
        pose_noise_rotation_deg: float = 0.0,
        seed: int = 0,
    ) -> None:
        for name, value in (
            ("pose_noise_translation", pose_noise_translation),
            ("pose_noise_rotation_deg", pose_noise_rotation_deg),
        ):
            if not (math.isfinite(value) and value >= 0):
                raise ValueError(f"{name}: must be >= 0, got {value!r}")
        if kinematics is not None and not isinstance(arm, JointArm):
            raise ValueError(f"arm: a cell with kinematics needs a JointArm, got {type(arm).__name__}")
        self.camera = camera
        self.arm: Any = arm
        self.kinematics = kinematics
        self.turntable = turntable
        self.config = config if config is not None else CellConfig()
        self.pose_noise_translation = float(pose_noise_translation)
        self.pose_noise_rotation = math.radians(pose_noise_rotation_deg)
        self._rng = np.random.default_rng(seed)
        self._arm_base = np.asarray(self.config.arm_base, dtype=np.float64)
        self.last_motion: Motion | None = None
        """The motion of the last :meth:`move_to` that started (the 3D view animates its trajectory)."""
        self.errors: Any = None
        """A simulated cell's calibration and motion errors (``devices.calibration_error.CellErrors``): the true
        transforms beside the nominal ones the cell reports; None for a real cell."""

    # ------------------------------------------------------------------ geometry

    @property
    def intrinsics(self) -> Intrinsics:
        return self.camera.intrinsics

    @property
    def angle(self) -> float:
        """The turntable angle theta, radians."""
        return self.turntable.angle

    @property
    def T_base_camera(self) -> Pose:
        """The true camera pose in the base frame: forward kinematics of the arm's joints, or the arm's pose."""
        if self.kinematics is not None:
            return self.kinematics.camera_pose(self.arm.joint_positions())
        return self.arm.pose

    @property
    def pose(self) -> Pose:
        """The true (noise-free) ``T_table_camera`` from the arm and the turntable angle."""
        return rz(-self.turntable.angle) @ self.T_base_camera

    def joint_positions(self) -> np.ndarray | None:
        """(n,) the arm's joints, radians (None for the reach-sphere arm)."""
        return self.arm.joint_positions() if self.kinematics is not None else None

    def set_object_box(self, bbox: BoundingBox | None) -> None:
        """The object's box B (table frame) the arm keeps clear of (padded by ``arm.object_padding``); None = none.
        The session calls it with the map's box before planning. No effect on the reach-sphere cell."""
        if self.kinematics is not None:
            if bbox is None:
                self.kinematics.set_object_box(None, None)
            else:
                self.kinematics.set_object_box(bbox.lower, bbox.upper)

    def plan_motion(self, T_table_camera: Pose, plate_angle: float | None = None, then: Sequence[Pose] = ()) -> Motion:
        """The turntable angle and arm motion that put the camera at ``T_table_camera``.

        URDF arm: the reachable, collision-free plate angle and IK solution with the shortest move, and its
        timed trajectory (:meth:`ArmKinematics.plan`); UnreachableError with ``reason`` otherwise.
        Reach sphere: theta turns the camera's azimuth onto the arm base's azimuth; a camera on
        the turntable axis keeps the current angle. Raises UnreachableError (with
        the numbers) when the camera would be below ``min_height`` above the plate
        top, or farther than ``arm_reach`` / nearer than ``arm_min_reach`` from the arm base.
        plate_angle: the plate must be at this angle (rad; a calibration pose): the URDF arm takes only that
        angle (one of its tried angles, else UnreachableError ``plate_angle``), the reach sphere uses it.
        then: the views (``T_table_camera`` each) the move after this one is expected to go to (a tour's
        ``PlanResult.then_poses``): the URDF arm takes the target whose move plus the quickest move on to one of
        them is shortest (:meth:`ArmReach.best_target`); the reach sphere ignores them.
        """
        if not isinstance(T_table_camera, Pose):
            raise ValueError(f"T_table_camera: expected a Pose, got {type(T_table_camera).__name__}")
        if self.kinematics is not None:
            move = self.kinematics.plan(
                T_table_camera, self.arm.joint_positions(), self.turntable.angle, plate_angle, then
            )
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
        x, y, z = T_table_camera.translation
        cfg = self.config
        if z < cfg.min_height:
            raise UnreachableError(
                f"unreachable: camera at height {z:.3f} m is below the plate top + clearance ({cfg.min_height:.3f} m)"
            )
        if plate_angle is not None:
            theta = wrap_angle(plate_angle)
        elif math.hypot(x, y) < 1e-9:
            theta = wrap_angle(self.turntable.angle)
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
        turn = abs(wrap_angle(theta - self.turntable.angle)) / math.radians(cfg.arm.turntable_speed_deg)
        travel = float(np.linalg.norm(T_base_camera.translation - self.arm.pose.translation))
        return Motion(theta, T_base_camera, duration=turn + travel / SPHERE_CAMERA_SPEED)

    def reachability(self, T_table_camera: Pose) -> tuple[bool, str | None]:
        """(reachable, reason): IK + joint limits + collisions at some plate angle for a URDF arm (reason
        ``no_ik``, ``joint_limit`` or ``collision:<link>:<obstacle>``); the reach test for the sphere (``reach``).
        The path itself is planned only on a move (``no_path`` then)."""
        if self.kinematics is not None:
            return self.kinematics.reachability(T_table_camera, self.arm.joint_positions(), self.turntable.angle)
        ok = self.is_reachable(T_table_camera)
        return ok, None if ok else "reach"

    def reachability_many(self, poses: list[Pose]) -> list[tuple[bool, str | None]]:
        """:meth:`reachability` of many views (e.g. all candidates of a plan, in their order: neighbours warm-start
        each other's IK)."""
        if self.kinematics is None:
            return [self.reachability(T) for T in poses]
        q, angle = self.arm.joint_positions(), self.turntable.angle
        return [self.kinematics.reachability(T, q, angle) for T in poses]

    def move_estimate(self, T_table_camera: Pose) -> float:
        """Seconds the move to a view would take from the current state (inf if unreachable): plate turn plus
        the slowest joint to the nearest target (every plate angle and IK branch; no path planned) for a URDF arm, plate turn plus the camera's straight travel at
        ``SPHERE_CAMERA_SPEED`` for the reach sphere."""
        if self.kinematics is not None:
            target, _ = self.kinematics.reach.best_target(
                T_table_camera, self.arm.joint_positions(), self.turntable.angle
            )
            return math.inf if target is None else target.move_estimate
        try:
            return self.plan_motion(T_table_camera).duration
        except UnreachableError:
            return math.inf

    def move_costs(self, candidates: Sequence[Any], eligible: NDArray[np.bool_]) -> NDArray[np.float64]:
        """(C,) :meth:`move_estimate` of each eligible candidate (``.T_world_camera``), inf for the others: the
        ``move_cost`` callable of ``Planner.plan``."""
        out = np.full(len(candidates), math.inf)
        for i in np.flatnonzero(np.asarray(eligible, dtype=bool)):
            out[i] = self.move_estimate(candidates[int(i)].T_world_camera)
        return out

    def move_times(
        self, candidates: Sequence[Any], indices: Sequence[int], *, exact: bool = False
    ) -> NDArray[np.float64]:
        """(K + 1, K + 1) estimated seconds of the move between every two of the current state and the K views
        ``candidates[indices]`` (``.T_world_camera``; inf to and from an unreachable one): the ``move_times`` of
        ``Planner.plan``. URDF arm: plate turn and the slowest joint's trapezoid (:meth:`ArmReach.move_seconds`:
        one after the other, or together when the arm stands clear of the turning object and the arm's config
        says so) between the views' cached reachability targets at every plate angle (:meth:`_cached_move_times`).
        exact: each view's target is instead the one a move from the current state would take (every plate angle
        the turn allows and every IK branch from the current joints, :meth:`ArmReach.best_target`; about 2.5 ms
        a view with the UR5's branches in closed form, 9.6 ms with seeded IK), so row 0 is the move's own estimate; a
        few views only (the tour's cover).
        Reach sphere: plate turn + the camera's straight travel at ``SPHERE_CAMERA_SPEED``."""
        poses = [candidates[int(i)].T_world_camera for i in indices]
        n = len(poses) + 1
        ok = np.ones(n, dtype=bool)
        if self.kinematics is not None:
            kinematics = self.kinematics
            reach = kinematics.reach
            q0, a0 = np.asarray(self.arm.joint_positions(), dtype=np.float64), self.turntable.angle
            if exact:

                def turn_check(a: float) -> str | None:
                    return kinematics.turn_blocked(q0, a0, a)

                qs, angles = [q0], [a0]
                for k, T in enumerate(poses, start=1):
                    best, _ = reach.best_target(T, q0, a0, turn_check)
                    ok[k] = best is not None
                    qs.append(q0 if best is None else best.q)
                    angles.append(a0 if best is None else best.angle)
                times = reach.seconds_between(np.stack(qs), np.array(angles), np.stack(qs), np.array(angles))
            else:
                times = self._cached_move_times(poses, q0, a0, ok)
        else:
            xyz, angles = [self.arm.pose.translation], [self.turntable.angle]
            for k, T in enumerate(poses, start=1):
                try:
                    motion = self.plan_motion(T)
                except UnreachableError:
                    ok[k] = False
                    xyz.append(xyz[0])
                    angles.append(angles[0])
                    continue
                xyz.append(motion.T_base_camera.translation)
                angles.append(motion.angle)
            from devices.arm.reach import turn_matrix

            turn = turn_matrix(np.array(angles))
            p = np.stack(xyz)
            travel = np.linalg.norm(p[:, None, :] - p[None, :, :], axis=2)
            times = turn / math.radians(self.config.arm.turntable_speed_deg) + travel / SPHERE_CAMERA_SPEED
        times[~ok, :] = math.inf
        times[:, ~ok] = math.inf
        np.fill_diagonal(times, 0.0)
        return times

    def _cached_move_times(
        self, poses: Sequence[Pose], q0: NDArray[np.float64], a0: float, ok: NDArray[np.bool_]
    ) -> NDArray[np.float64]:
        """:meth:`move_times` from the cached reachability targets (``ok`` (K + 1,) is set False for the views none
        of whose plate angles has a free target). Each view's entry target: of its free targets at every plate
        angle (:meth:`ArmReach.free_targets`), the one with the shortest move from the current state (q0 (n,),
        plate angle a0); the move from view i to view j: from i's entry target to the nearest of j's targets."""
        assert self.kinematics is not None
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

    def is_reachable(self, T_table_camera: Pose) -> bool:
        """Whether the view is reachable (:meth:`reachability`; for the sphere in closed form, no Pose built).

        The reach sphere turns the camera onto the arm base's azimuth, so its distance to
        the base is that of two points in one vertical half-plane.
        """
        if self.kinematics is not None:
            return self.reachability(T_table_camera)[0]
        x, y, z = T_table_camera.translation
        cfg = self.config
        if z < cfg.min_height:
            return False
        base_radial = math.hypot(self._arm_base[0], self._arm_base[1])
        distance = math.hypot(math.hypot(x, y) - base_radial, z - self._arm_base[2])
        return cfg.arm_min_reach <= distance <= cfg.arm_reach

    def initial_pose(self) -> Pose:
        """``T_table_camera`` of the first view: at ``initial_elevation_deg`` / ``initial_azimuth_deg`` /
        ``initial_distance`` about the point ``initial_target_height`` above the plate centre, looking at it.
        """
        cfg = self.config
        e, a = math.radians(cfg.initial_elevation_deg), math.radians(cfg.initial_azimuth_deg)
        target = np.array([0.0, 0.0, cfg.initial_target_height])
        eye = target + cfg.initial_distance * np.array(
            [math.cos(e) * math.cos(a), math.cos(e) * math.sin(a), math.sin(e)]
        )
        return Pose.look_at(eye, target)

    # ------------------------------------------------------------------ safety and life cycle

    def auto_refusal(self) -> str | None:
        """Why moves without an approval per view (step, auto mode) may not run on this cell; None: they may."""
        return None

    def halt(self) -> list[str] | None:
        """Stop a running move at once; None when this cell cannot (a simulated cell ends its move quickly),
        else the drivers' errors (a cell on real devices, :class:`devices.hwcell.HardwareCell`)."""
        return None

    @property
    def halting(self) -> bool:
        """A halt was asked and the move it stopped has not ended yet."""
        return False

    def close(self) -> None:
        """Release the devices (a cell on real devices closes them; here nothing to do)."""

    # ------------------------------------------------------------------ actions

    def move_to(self, T_table_camera: Pose, plate_angle: float | None = None, then: Sequence[Pose] = ()) -> Motion:
        """Turn the plate, then move the arm, so the camera is at ``T_table_camera`` (a URDF arm retracts first
        when the turn would sweep the object's box into it: ``Motion.retract``; with ``Motion.overlapped`` the plate
        turns while the arm moves).

        Plans first (``plate_angle``, ``then``: as in :meth:`plan_motion`): an unreachable view raises
        UnreachableError and moves nothing.
        A device fault (DeviceError) after the turntable moved leaves the plate at its
        new angle; a fault during the trajectory leaves the arm where it stopped.
        """
        motion = self.plan_motion(T_table_camera, plate_angle, then)
        self.last_motion = motion
        if motion.retract is not None:
            self.arm.execute(motion.retract)
        if motion.overlapped and motion.trajectory is not None:
            self._turn_during(motion.angle, motion.trajectory)
            return motion
        self.turntable.rotate_to(motion.angle)
        if motion.trajectory is not None:
            self.arm.execute(motion.trajectory)
        else:
            self.arm.move_to(motion.T_base_camera)
        return motion

    def _turn_during(self, angle: float, trajectory: JointTrajectory) -> None:
        """Turn the plate to ``angle`` (a thread of its own) while the arm runs ``trajectory`` (this thread); both
        have ended when it returns. A fault of either stops the other and is raised (the turntable's first)."""
        failed: list[BaseException] = []

        def turn() -> None:
            try:
                self.turntable.rotate_to(angle)
            except BaseException as exc:  # handed to the caller's thread
                failed.append(exc)
                self.arm.stop()

        turning = threading.Thread(target=turn, name="turntable", daemon=True)
        turning.start()
        try:
            self.arm.execute(trajectory)
        except BaseException:
            stop = getattr(self.turntable, "stop", None)
            if callable(stop):
                stop()
            turning.join()
            if failed:
                raise failed[0] from None
            raise
        turning.join()
        if failed:
            raise failed[0]

    def capture(self) -> DepthFrame:
        """A depth image with ``T_world_camera`` = the camera pose in the table frame.

        The pose is ``Rz(-theta) @ arm.pose``, perturbed by the configured pose noise
        (a fresh draw per capture); the image itself was taken from the true pose.
        """
        frame = self.camera.capture()
        return frame.with_pose(self._perturb(self.pose))

    def device_state(self) -> dict[str, Any]:
        """What a resumed session needs to continue exactly: the pose-noise RNG state, the camera's
        ``device_state()`` (its noise RNG, or a replay camera's position) and, for a URDF arm, its joints and the
        plate angle (a resumed session moves on from the same configuration, so it picks the same IK branches).
        JSON-ready."""
        state: dict[str, Any] = {"pose_noise": self._rng.bit_generator.state}
        camera_state = getattr(self.camera, "device_state", None)
        if callable(camera_state):
            state["camera"] = camera_state()
        if self.kinematics is not None:
            state["arm"] = {"q": [float(v) for v in self.arm.joint_positions()], "angle": float(self.turntable.angle)}
        return state

    def restore_device_state(self, state: dict[str, Any]) -> None:
        """Undo :meth:`device_state`: the next capture draws the noise it would have drawn; a simulated arm and
        turntable are put back where they were (a real one is not: it moves only by trajectories).
        ValueError if malformed."""
        try:
            if "pose_noise" in state:
                self._rng.bit_generator.state = state["pose_noise"]
            restore = getattr(self.camera, "restore_device_state", None)
            if "camera" in state and callable(restore):
                restore(state["camera"])
            arm_state = state.get("arm")
            reset_arm, reset_table = getattr(self.arm, "reset", None), getattr(self.turntable, "reset", None)
            if self.kinematics is not None and arm_state is not None and callable(reset_arm) and callable(reset_table):
                q = np.array(arm_state["q"], dtype=np.float64)
                if q.shape != (len(self.arm.joint_names),) or not np.all(np.isfinite(q)):
                    raise ValueError(f"arm joints {arm_state['q']!r}")
                reset_arm(q)
                reset_table(float(arm_state["angle"]))
        except (TypeError, KeyError, ValueError) as exc:
            raise ValueError(f"device state: cannot restore ({exc})") from None

    def _perturb(self, pose: Pose) -> Pose:
        if self.pose_noise_translation == 0 and self.pose_noise_rotation == 0:
            return pose
        dt: NDArray[np.float64] = (
            self._rng.normal(0.0, self.pose_noise_translation, 3) if self.pose_noise_translation else np.zeros(3)
        )
        rotvec = self._rng.normal(0.0, self.pose_noise_rotation, 3) if self.pose_noise_rotation else np.zeros(3)
        dR = Rotation.from_rotvec(rotvec).as_matrix()
        return Pose(pose.rotation @ dR, pose.translation + dt)
