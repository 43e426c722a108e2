"""The arm side of the cell in one object: model, collision world, reachability and motion planning.

:class:`ArmKinematics` is what :class:`devices.cell.Cell` uses when the cell has a real arm model
(``CellConfig.kinematics == "urdf"``): it answers whether a view is reachable (and why not), picks the plate
angle and joint target with the shortest move, plans and times the joint trajectory, and gives the camera pose
of any configuration by forward kinematics. It moves nothing: the cell sends the result to the devices.
"""

from __future__ import annotations

import dataclasses
import itertools
import math
import time
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from devices.angles import wrap_angle
from devices.arm.collision import CollisionWorld
from devices.arm.config import ArmConfig
from devices.arm.ik import dls
from devices.arm.model import ArmModel, load_arm
from devices.arm.motion import NoPathError, plan_path, time_path
from devices.arm.reach import ArmReach, ArmTarget, rz_matrix
from devices.protocols import UnreachableError
from devices.trajectory import JointTrajectory
from planner.types import Pose

REFINE_TOLERANCE = 1e-9
"""A move's joint target is polished to this IK tolerance (metres; radians x 10)."""
REFINE_ITERATIONS = 10
"""Damped least squares iterations of that polish (from a converged solution it needs one or two)."""
TURN_CHECKS_PER_RADIAN = 12
"""While the plate turns, the arm (standing still) is checked against the turning object this often."""


@dataclass(frozen=True, eq=False)
class ArmMove:
    """A planned move: the target, the timed trajectory, and what it costs.

    target: plate angle, joint target q (n,), ``T_base_camera``. trajectory: the arm's joint trajectory (it runs
    after the plate has turned). turn_seconds: the plate's turn. path_method: 'straight' or 'rrt_connect'.
    planning_seconds: time spent choosing the target and planning the path. retract: when the turn would sweep
    the object's box into the standing arm, the trajectory to the retracted (home) configuration that runs
    before the turn (the main trajectory then starts there); None otherwise. overlapped: the plate turns while
    the main trajectory runs (``ArmConfig.turn_while_moving`` and every configuration of its path clear of the
    turning object, :meth:`ArmKinematics.path_sweep_free`); False: the turn, then the trajectory.
    """

    target: ArmTarget
    trajectory: JointTrajectory
    turn_seconds: float
    path_method: str
    planning_seconds: float
    retract: JointTrajectory | None = None
    overlapped: bool = False

    @property
    def duration(self) -> float:
        """Seconds of the whole move: the retract (if any), then the plate's turn and the arm's trajectory, one
        after the other (their sum) or together (the longer, when ``overlapped``)."""
        before = self.retract.duration if self.retract is not None else 0.0
        if self.overlapped:
            return before + max(self.turn_seconds, self.trajectory.duration)
        return before + self.turn_seconds + self.trajectory.duration


class ArmKinematics:
    """config: the arm. plate_radius, plate_thickness: the turntable (``CellConfig``), metres."""

    def __init__(self, config: ArmConfig, plate_radius: float, plate_thickness: float) -> None:
        if math.hypot(config.mount[0], config.mount[1]) < plate_radius:
            raise ValueError(
                f"arm.base: {config.mount} is inside the plate (radius {plate_radius} m about the origin); "
                "put the arm beside the turntable"
            )
        self.config = config
        # the model (cached per config) does not depend on how the cell times its moves: one model for both
        self.model: ArmModel = load_arm(dataclasses.replace(config, turn_while_moving=False), config.mount)
        self.world = CollisionWorld(self.model, plate_radius, plate_thickness)
        home = np.radians(config.home) if len(config.home) == self.model.nq else np.zeros(self.model.nq)
        self.home: NDArray[np.float64] = np.clip(home, self.model.lower, self.model.upper)
        self.reach = ArmReach(self.model, self.world, self.home, turn_while_moving=config.turn_while_moving)
        self._turn_hits: dict[tuple[bytes, float], str | None] = {}
        # (configuration, plate angle, direction) -> (grid points walked, (k, collision) of the first that collides)
        self._turn_walks: dict[tuple[bytes, float, float], tuple[int, tuple[int, str] | None]] = {}
        self.use_sweep_test = True
        """False: every turn is checked on its grid (the reference the sweep test is tested against)."""

    @property
    def joint_names(self) -> tuple[str, ...]:
        return self.model.joint_names

    def camera_pose(self, q: NDArray[np.float64]) -> Pose:
        """``T_base_camera`` of configuration (n,) ``q`` (forward kinematics)."""
        return self.model.camera_pose(q)

    def set_object_box(self, lower_table: NDArray[np.float64] | None, upper_table: NDArray[np.float64] | None) -> None:
        """The object's box (table frame, (3,) corners) the arm must keep clear of; None = no object model yet."""
        self.world.set_object_box(lower_table, upper_table)
        self._turn_hits.clear()
        self._turn_walks.clear()

    def turn_collision(self, q: NDArray[np.float64], angle: float, turn: float) -> str | None:
        """The first collision of the arm standing at (n,) ``q`` while the plate turns from ``angle`` by ``turn``
        radians (the object's box turning with it), or None. Checked on a fixed grid of plate angles
        (``TURN_CHECKS_PER_RADIAN``) plus the end, cached per configuration: the planner's reachability of 400
        views and the move ask the same question with the same answer. The grid's first collision each way from
        ``angle`` is kept too, so the 400 views' turns from one state cost one walk of the grid, not one each."""
        q = np.asarray(q, dtype=np.float64)
        if self.use_sweep_test and self.reach.sweep_free(q):
            return None  # clear of everything the box sweeps: no turn collides (the same answer as the checks)
        q_key = q.tobytes()
        n = math.floor(abs(turn) / (1.0 / TURN_CHECKS_PER_RADIAN))
        hit = self._grid_turn_hit(q, q_key, angle, math.copysign(1.0, turn), n)
        return hit if hit is not None else self._turn_hit(q, q_key, angle + turn)

    def _grid_turn_hit(self, q: NDArray[np.float64], q_key: bytes, angle: float, sign: float, n: int) -> str | None:
        """The first collision at the grid angles ``angle + sign * k / TURN_CHECKS_PER_RADIAN``, k = 0 .. n, or None;
        the grid is walked once per (configuration, angle, direction) and only as far as asked."""
        key = (q_key, angle, sign)
        walked, first = self._turn_walks.get(key, (0, None))
        if first is None and walked <= n:
            step = 1.0 / TURN_CHECKS_PER_RADIAN
            for k in range(walked, n + 1):
                hit = self._turn_hit(q, q_key, angle + math.copysign(k * step, sign))
                if hit is not None:
                    first = (k, hit)
                    break
            walked = max(walked, n + 1) if first is None else first[0] + 1
            if len(self._turn_walks) >= 10_000:
                self._turn_walks.clear()
            self._turn_walks[key] = (walked, first)
        return first[1] if first is not None and first[0] <= n else None

    def _turn_hit(self, q: NDArray[np.float64], q_key: bytes, plate_angle: float) -> str | None:
        """The collision of the arm at ``q`` with the plate at ``plate_angle`` (cached per configuration and angle)."""
        key = (q_key, round(plate_angle, 9))
        if key not in self._turn_hits:
            if len(self._turn_hits) >= 100_000:
                self._turn_hits.clear()
            self._turn_hits[key] = self.world.turning_collision(q, plate_angle)
        return self._turn_hits[key]

    def turn_blocked(self, q: NDArray[np.float64], angle: float, target_angle: float) -> str | None:
        """Why the plate cannot turn from ``angle`` to ``target_angle`` even with the arm retracted to ``home``
        first (``turn:<collision>``), or None (the turn is clear from ``q``, or from home)."""
        turn = wrap_angle(target_angle - angle)
        if self.turn_collision(q, angle, turn) is None:
            return None
        hit = self.turn_collision(self.home, angle, turn)
        return None if hit is None else f"turn:{hit}"

    def path_sweep_free(self, waypoints: NDArray[np.float64]) -> bool:
        """Whether every configuration of the joint path (K, n) ``waypoints``, checked every
        ``arm.path_resolution_deg`` of the largest joint step as the path itself was, stands clear of the cylinder
        the padded object box sweeps (:meth:`ArmReach.sweep_free`): then the plate may turn while the arm runs
        the path, whatever the timing of the two."""
        resolution = math.radians(self.config.path_resolution_deg)
        waypoints = np.asarray(waypoints, dtype=np.float64)
        if not self.reach.sweep_free(waypoints[0]):
            return False
        for a, b in itertools.pairwise(waypoints):
            steps = max(1, math.ceil(float(np.max(np.abs(b - a))) / resolution))
            for t in np.linspace(0.0, 1.0, steps + 1)[1:]:
                if not self.reach.sweep_free(a + t * (b - a)):
                    return False
        return True

    def reachability(self, T_table_camera: Pose, q: NDArray[np.float64], angle: float) -> tuple[bool, str | None]:
        """(reachable, reason) of a view from the state (q, plate angle): a free IK target at some plate angle,
        and a plate turn to it that does not sweep the object's box into the arm (standing, or retracted)."""
        target_angle, reason = self.reach.reachable_angle(T_table_camera, q, angle)
        if target_angle is None:
            return False, reason
        if self.turn_blocked(q, angle, target_angle) is None:
            return True, None
        target, reason = self.reach.best_target(  # another plate angle may turn clear
            T_table_camera, q, angle, lambda a: self.turn_blocked(q, angle, a)
        )
        return target is not None, reason

    def violations(self, q: NDArray[np.float64], angle: float) -> str | None:
        """Why configuration (n,) ``q`` at plate ``angle`` is not allowed ('joint_limit' or a collision), or None."""
        if not self.model.within_limits(np.asarray(q, dtype=np.float64)):
            return "joint_limit"
        return self.world.collision(np.asarray(q, dtype=np.float64), angle)

    def _refined(self, T_table_camera: Pose, target: ArmTarget) -> ArmTarget:
        """The target with its joints polished to ``REFINE_TOLERANCE`` (the camera lands on the view to about a
        micrometre, not just within the IK tolerance), if the polished joints are still inside the limits and free."""
        import pinocchio as pin  # pyright: ignore[reportMissingImports]  (under cmeel.prefix)

        R = rz_matrix(target.angle)
        M = pin.SE3(R @ T_table_camera.rotation, R @ T_table_camera.translation)
        q = dls(self.model, self.model.model.createData(), M, target.q, REFINE_ITERATIONS, REFINE_TOLERANCE)
        if q is None or self.violations(q, target.angle) is not None:
            return target
        return ArmTarget(target.angle, q, self.camera_pose(q), target.move_estimate)

    def plan(
        self,
        T_table_camera: Pose,
        q: NDArray[np.float64],
        angle: float,
        plate_angle: float | None = None,
        then: Sequence[Pose] = (),
    ) -> ArmMove:
        """The move to a view from the state (q (n,), plate angle): the reachable, collision-free target with the
        shortest move and its trajectory. UnreachableError(reason) when there is none.
        plate_angle: only this plate angle (rad) is allowed (a calibration pose; it must be one of the angles
        :meth:`ArmReach.plate_angles` tries, reason ``plate_angle`` otherwise). then: the views the next move is
        expected to go to; the target is then the one whose move plus the quickest move on is shortest
        (:meth:`ArmReach.best_target`)."""
        t0 = time.perf_counter()
        q = np.asarray(q, dtype=np.float64)

        def turn_check(a: float) -> str | None:
            if plate_angle is not None and abs(wrap_angle(a - plate_angle)) > 1e-9:
                return "plate_angle"
            return self.turn_blocked(q, angle, a)

        target, reason = self.reach.best_target(T_table_camera, q, angle, turn_check, then)
        if target is None:
            raise UnreachableError(f"unreachable: {reason}", reason=reason or "no_ik")
        target = self._refined(T_table_camera, target)
        turn = wrap_angle(target.angle - angle)
        retract = None
        start = q
        hit = self.turn_collision(q, angle, turn)
        if hit is not None:  # what a real cell does: retract the arm, turn, then go to the view
            home_hit = self.turn_collision(self.home, angle, turn)
            if home_hit is not None:
                raise UnreachableError(
                    f"unreachable: {hit} while the plate turns, and {home_hit} with the arm retracted",
                    reason=f"turn:{home_hit}",
                )
            try:
                back = plan_path(self.world, q, self.home, angle)
            except NoPathError as exc:
                raise UnreachableError(f"unreachable: retract before the turn: {exc}", reason="no_path") from None
            retract, start = time_path(self.model, back.waypoints), self.home
        try:
            path = plan_path(self.world, start, target.q, target.angle)
        except NoPathError as exc:
            raise UnreachableError(f"unreachable: {exc}", reason="no_path") from None
        trajectory = time_path(self.model, path.waypoints)
        turn_seconds = self.reach.turn_seconds(angle, target.angle)
        overlapped = self.config.turn_while_moving and turn_seconds > 0 and self.path_sweep_free(path.waypoints)
        return ArmMove(target, trajectory, turn_seconds, path.method, time.perf_counter() - t0, retract, overlapped)
