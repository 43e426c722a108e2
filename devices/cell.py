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

The two are the two implementations of :class:`devices.cellreach.Reach` (``UrdfArm``, ``SphereReach``) the cell
holds as ``Cell.reach``. In both, the arm moves the camera to ``T_base_camera = Rz(theta) @ T_table_camera``.
:class:`ScanCell` is what a scan asks of a cell (the session, ``workbench.planning.plan_in``, the headless scan):
every capability is a method every cell has, answering "none" where it is absent.
``devices.sim.make_sim_cell`` builds a Cell of simulated devices.
"""

from __future__ import annotations

import math
import threading
from collections.abc import Sequence
from typing import TYPE_CHECKING, Any, Protocol, cast

import numpy as np
from numpy.typing import NDArray
from scipy.spatial.transform import Rotation

from devices.cellreach import Reach, SphereReach, UrdfArm
from devices.config import CellConfig
from devices.motion import Motion, rz
from devices.move_capture import MoveFrame, MovePath, OnFrame, SimulatedMoveCapture, capture_times
from devices.protocols import Arm, Camera, JointArm, Turntable
from devices.trajectory import JointTrajectory
from planner.config import PlannerConfig
from planner.types import BoundingBox, CameraPath, DepthFrame, Intrinsics, Pose

if TYPE_CHECKING:
    from devices.arm.kinematics import ArmKinematics

__all__ = ["Cell", "Motion", "MoveFrame", "ScanCell", "rz"]


class ScanCell(Protocol):
    """What a scan asks of a cell: planning (reachability, the object box, move costs and times), the moves, the
    captures, the device state a resume restores, and the safety of a cell on real devices. Optional capabilities
    are methods every cell has: ``set_object_box`` does nothing without a collision model, ``halt`` returns None
    for a cell that cannot halt, ``auto_refusal`` None where auto mode may run, ``knows_pose`` False for a
    device-less planning cell (no move times from it)."""

    @property
    def config(self) -> CellConfig:
        """The cell geometry (a worker's planning cell is built from it)."""
        ...

    @property
    def intrinsics(self) -> Intrinsics: ...

    @property
    def angle(self) -> float:
        """The turntable angle, radians."""
        ...

    @property
    def knows_pose(self) -> bool:
        """Whether the cell knows where its camera is (move times start from there)."""
        ...

    @property
    def reach_of_config(self) -> bool:
        """Whether a worker's planning cell of the same config and arm state judges reachability the same."""
        ...

    @property
    def halting(self) -> bool:
        """A halt was asked and the move it stopped has not ended yet."""
        ...

    def initial_pose(self) -> Pose:
        """``T_table_camera`` of the first view."""
        ...

    def joint_positions(self) -> NDArray[np.float64] | None:
        """(n,) the arm's joints, None for an arm without joints."""
        ...

    def is_reachable(self, T_table_camera: Pose) -> bool: ...

    def candidate_poses(self) -> Sequence[Pose] | None:
        """The views the planner must choose among (``T_table_camera`` each: a recorded set's views), None: the
        planner proposes its own (the paper's hemisphere)."""
        ...

    def planner_config(self, config: PlannerConfig) -> PlannerConfig:
        """``config`` with what this cell's world implies for the planner (a recorded set seen from under the plate
        top has no floor); unchanged for a cell with a plate."""
        ...

    def set_object_box(self, bbox: BoundingBox | None) -> None:
        """The object's box the arm keeps clear of (nothing to do without a collision model)."""
        ...

    def move_costs(self, candidates: Sequence[Any], eligible: NDArray[np.bool_]) -> NDArray[np.float64]:
        """(C,) seconds of the move to each eligible candidate, inf for the others."""
        ...

    def move_times(
        self, candidates: Sequence[Any], indices: Sequence[int], *, exact: bool = False
    ) -> NDArray[np.float64]:
        """(K + 1, K + 1) seconds of the moves between the current state and the views ``indices``."""
        ...

    def move_paths(self, candidates: Sequence[Any], indices: Sequence[int], hz: float) -> list[CameraPath | None]:
        """Per view ``candidates[i]``, the camera's path on the move from the current state, frames at ``hz``
        (None: unreachable): the ``move_paths`` of ``Planner.plan``."""
        ...

    def plan_motion(self, T_table_camera: Pose, plate_angle: float | None = None, then: Sequence[Pose] = ()) -> Motion:
        """The motion to a view; UnreachableError when there is none."""
        ...

    def move_to(
        self,
        T_table_camera: Pose,
        plate_angle: float | None = None,
        then: Sequence[Pose] = (),
        motion: Motion | None = None,
        capture_hz: float = 0.0,
        on_frame: OnFrame | None = None,
    ) -> Motion:
        """Move to a view (by ``motion`` when it was planned already); returns the motion run. capture_hz > 0: the
        cell calls ``on_frame(MoveFrame)`` for each frame taken during the move, in stamp order, as they are taken
        (a cell that cannot capture while moving, or a move that is not timed, takes none)."""
        ...

    def stop_moving(self) -> None:
        """Stop the arm and the turntable (those whose driver can stop) after a move timed out."""
        ...

    def capture(self) -> DepthFrame: ...

    def device_state(self) -> dict[str, Any]: ...

    def restore_device_state(self, state: dict[str, Any]) -> None: ...

    def auto_refusal(self) -> str | None:
        """Why moves without an approval per view may not run on this cell; None: they may."""
        ...

    def halt(self) -> list[str] | None:
        """Stop a running move at once; None when this cell cannot."""
        ...

    def close(self) -> None: ...


class Cell:
    """A camera, an arm and a turntable working together in the table frame.

    camera, arm, turntable: any objects satisfying the protocols in ``devices.protocols`` (the arm a
    ``JointArm`` when ``kinematics`` is given, else an ``Arm``).
    config: the cell geometry (arm base, reach, plate).
    kinematics: the arm model that plans the moves of a ``JointArm`` (None = the reach sphere of ``config``).
    reach: how the arm reaches a view (:class:`devices.cellreach.Reach`; None: :class:`UrdfArm` of ``kinematics``,
    else :class:`SphereReach` of ``config``).
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
        reach: Reach | None = None,
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
        self._config = config if config is not None else CellConfig()
        self.pose_noise_translation = float(pose_noise_translation)
        self.pose_noise_rotation = math.radians(pose_noise_rotation_deg)
        self._rng = np.random.default_rng(seed)
        if reach is None:
            if kinematics is None:
                reach = SphereReach(self._config, cast("Arm | None", arm), turntable)
            else:
                reach = UrdfArm(kinematics, cast(JointArm, arm), turntable)  # a JointArm: checked above
        self.reach: Reach = reach
        self.last_motion: Motion | None = None
        """The motion of the last :meth:`move_to` that started (the 3D view animates its trajectory)."""
        self.move_capture: SimulatedMoveCapture | None = None
        """A simulated cell's renderer of the frames taken during a move (``Cell.move_to(capture_hz=...)``); None: the
        cell takes none (a real cell captures from its stream instead)."""
        self.errors: Any = None
        """A simulated cell's calibration and motion errors (``devices.calibration_error.CellErrors``): the true
        transforms beside the nominal ones the cell reports; None for a real cell."""

    # ------------------------------------------------------------------ geometry

    @property
    def config(self) -> CellConfig:
        """The cell geometry (arm base, reach, plate, initial view); set, the reach answers from the new one."""
        return self._config

    @config.setter
    def config(self, config: CellConfig) -> None:
        self._config = config
        self.reach.set_config(config)

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
        return self.reach.camera_pose()

    @property
    def pose(self) -> Pose:
        """The true (noise-free) ``T_table_camera`` from the arm and the turntable angle."""
        return rz(-self.turntable.angle) @ self.T_base_camera

    @property
    def knows_pose(self) -> bool:
        """Whether the cell knows where its camera is (a device-less planning cell of the reach sphere does not):
        move times between views start from there."""
        return self.arm is not None

    @property
    def reach_of_config(self) -> bool:
        """Whether reachability is that of ``config`` and the arm's state alone, so a worker's planning cell of the
        same config and state answers the same (a replay cell judges it its own way)."""
        return True

    def joint_positions(self) -> NDArray[np.float64] | None:
        """(n,) the arm's joints, radians (None for the reach-sphere arm)."""
        return self.reach.joint_positions()

    def candidate_poses(self) -> Sequence[Pose] | None:
        """None: the planner proposes its candidates (a recorded set's cell gives its views instead)."""
        return None

    def planner_config(self, config: PlannerConfig) -> PlannerConfig:
        """``config`` unchanged: the plate hides what lies under its top (``voxel.floor``) as the config says."""
        return config

    def set_object_box(self, bbox: BoundingBox | None) -> None:
        """The object's box B (table frame) the arm keeps clear of (padded by ``arm.object_padding``); None = none.
        The session calls it with the map's box before planning. No effect on the reach-sphere cell."""
        self.reach.set_object_box(bbox)

    def plan_motion(self, T_table_camera: Pose, plate_angle: float | None = None, then: Sequence[Pose] = ()) -> Motion:
        """The turntable angle and arm motion that put the camera at ``T_table_camera`` (:meth:`Reach.plan`).

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
        return self.reach.plan(T_table_camera, plate_angle, then)

    def reachability(self, T_table_camera: Pose) -> tuple[bool, str | None]:
        """(reachable, reason): IK + joint limits + collisions at some plate angle for a URDF arm (reason
        ``no_ik``, ``joint_limit`` or ``collision:<link>:<obstacle>``); the reach test for the sphere (``reach``).
        The path itself is planned only on a move (``no_path`` then)."""
        return self.reach.reachability(T_table_camera)

    def reachability_many(self, poses: list[Pose]) -> list[tuple[bool, str | None]]:
        """:meth:`reachability` of many views (e.g. all candidates of a plan, in their order: neighbours warm-start
        each other's IK)."""
        return self.reach.reachability_many(poses)

    def move_estimate(self, T_table_camera: Pose) -> float:
        """Seconds the move to a view would take from the current state (inf if unreachable): plate turn plus
        the slowest joint to the nearest target (every plate angle and IK branch; no path planned) for a URDF arm,
        plate turn plus the camera's straight travel at ``SPHERE_CAMERA_SPEED`` for the reach sphere."""
        return self.reach.move_estimate(T_table_camera)

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
        says so) between the views' cached reachability targets at every plate angle (:meth:`UrdfArm.move_times`).
        exact: each view's target is instead the one a move from the current state would take (every plate angle
        the turn allows and every IK branch from the current joints, :meth:`ArmReach.best_target`; about 2.5 ms
        a view with the UR5's branches in closed form, 9.6 ms with seeded IK), so row 0 is the move's own estimate; a
        few views only (the tour's cover).
        Reach sphere: plate turn + the camera's straight travel at ``SPHERE_CAMERA_SPEED``."""
        times, ok = self.reach.move_times([candidates[int(i)].T_world_camera for i in indices], exact)
        times[~ok, :] = math.inf
        times[:, ~ok] = math.inf
        np.fill_diagonal(times, 0.0)
        return times

    def move_paths(self, candidates: Sequence[Any], indices: Sequence[int], hz: float) -> list[CameraPath | None]:
        """Per view ``candidates[i]`` (``.T_world_camera``) for i in ``indices``: the camera's path on the move from
        the current state, ``T_table_camera`` where each frame taken at ``hz`` during the move would be
        (``devices.move_capture.capture_times``) and the move's seconds; None for a view the cell cannot reach. The
        ``move_paths`` of ``Planner.plan``: an estimate for planning, no motion planned (:meth:`Reach.move_paths`:
        exact for the reach sphere; the URDF arm's cached target, plate turn, then a straight joint path). ValueError
        for a bad rate."""
        capture_times(1.0, hz)  # a bad rate raises
        return self.reach.move_paths([candidates[int(i)].T_world_camera for i in indices], hz)

    def is_reachable(self, T_table_camera: Pose) -> bool:
        """Whether the view is reachable (:meth:`reachability`; for the sphere in closed form, no Pose built)."""
        return self.reach.is_reachable(T_table_camera)

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

    def move_to(
        self,
        T_table_camera: Pose,
        plate_angle: float | None = None,
        then: Sequence[Pose] = (),
        motion: Motion | None = None,
        capture_hz: float = 0.0,
        on_frame: OnFrame | None = None,
    ) -> Motion:
        """Turn the plate, then move the arm, so the camera is at ``T_table_camera`` (a URDF arm retracts first
        when the turn would sweep the object's box into it: ``Motion.retract``; with ``Motion.overlapped`` the plate
        turns while the arm moves). Returns the motion it ran.

        motion: the motion to run, planned already by :meth:`plan_motion` for this view from the current state
        (an approval checks the view by planning it, and that plan is the one executed); None, or one the arm has
        moved away from since (:meth:`Reach.is_current`): planned here (``plate_angle``, ``then``: as in
        :meth:`plan_motion`), an unreachable view raising UnreachableError with nothing moved.
        capture_hz, on_frame: capture during the move: ``on_frame(MoveFrame)`` for each frame taken at
        ``capture_hz`` along the path the cell executes (:class:`devices.move_capture.MovePath`), in stamp order; a
        simulated cell (``move_capture`` set) renders them after its instant move, each reported at the nominal pose
        of its stamp (with the cell's pose noise), rendered from the true one (the sensor's timing model). 0 or no
        ``on_frame``: none. ValueError for a bad rate, with nothing moved.
        A device fault (DeviceError) after the turntable moved leaves the plate at its
        new angle; a fault during the trajectory leaves the arm where it stopped.
        """
        capture_times(1.0, capture_hz)  # a bad rate raises before anything moves
        if motion is None or not self.reach.is_current(motion):
            motion = self.plan_motion(T_table_camera, plate_angle, then)
        self.last_motion = motion
        path = None
        if capture_hz > 0 and on_frame is not None and motion.timed and self.move_capture is not None:
            path = MovePath.of(self, motion)
        self._run(motion)
        if path is not None and on_frame is not None and self.move_capture is not None:
            for taken in self.move_capture.frames(path, capture_hz):
                reported = taken.frame.with_pose(self._perturb(taken.frame.T_world_camera))
                on_frame(MoveFrame(reported, taken.t, taken.speed))
        return motion

    def _run(self, motion: Motion) -> None:
        """Send ``motion`` to the devices: the retract, then the turn and the trajectory (or both at once)."""
        if motion.retract is not None:
            self.arm.execute(motion.retract)
        if motion.overlapped and motion.trajectory is not None:
            self._turn_during(motion.angle, motion.trajectory)
            return
        self.turntable.rotate_to(motion.angle)
        if motion.trajectory is not None:
            self.arm.execute(motion.trajectory)
        else:
            self.arm.move_to(motion.T_base_camera)

    def stop_moving(self) -> None:
        """Stop the arm and the turntable (those whose driver has a ``stop()``), e.g. after a move timed out."""
        for device in (self.arm, self.turntable):
            _stop(device)

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
            _stop(self.turntable)
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
        arm_state = self.reach.arm_state()
        if arm_state is not None:
            state["arm"] = arm_state
        if self.move_capture is not None:
            state["move_capture"] = self.move_capture.device_state()
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
            if arm_state is not None:
                self.reach.restore_arm(arm_state)
            if "move_capture" in state and self.move_capture is not None:
                self.move_capture.restore_device_state(state["move_capture"])
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


def _stop(device: object) -> None:
    """``device.stop()`` for a driver that has one (a ``JointArm`` has; an ``Arm`` or a ``Turntable`` may)."""
    stop = getattr(device, "stop", None)
    if callable(stop):
        stop()
