"""Where the arm can put the camera: plate angle + IK + joint limits + collisions, per view, with its reason.

A view ``T_table_camera`` (the planner's world is the table frame) is reached by turning the plate to some angle
theta and moving the arm so that ``T_base_camera = Rz(theta) @ T_table_camera``. The plate angles tried put the
view's azimuth at the arm's azimuth plus each of ``ArmConfig.plate_offsets_deg``. A view is *reachable* when
one of them has an IK solution inside the joint limits, free of collisions; otherwise the reason of the attempt
that got furthest is kept: ``no_ik`` < ``joint_limit`` < ``collision:<link>:<obstacle>``.

Reachability is a pure function of the view and the object box (not of the arm's state or of what was asked
before), so replaying a journal gives the same eligible candidates. Speed (400 candidates per plan): IK is
seeded by the solution of an *anchor*, the centre of the view's cell on a coarse pose grid (solved once, kept
for the process and shared by the cells of one arm like the library: with the turntable, successive plans put
their candidates in the same cells, and so do the sessions of one cell), then by a library of configurations
sampled at start-up; results are cached by exact pose; a reach bound answers
``no_ik`` for far poses without IK; the plate offset that served the previous view is tried first (the
verdict does not depend on the order). The whole attempt at one plate angle (IK, joint limits, collisions) is
cached per (view, plate angle, padded object box): a pure function of the three, so a plan whose candidates and
box are those of an earlier plan (the box changes a few times per scan; the candidates only with it) answers
from the cache, with the same targets as without it (``tests/devices/test_reach_cache.py``).

A *move* (:meth:`ArmReach.best_target`) wants every IK branch at every plate angle, the shortest free one: for a
UR-type arm (the UR5) they come in closed form (:mod:`devices.arm.closed_form`, all eight, exact), checked for
collisions nearest move first; for any other arm, from damped least squares seeded by the current joints, the
anchor and the library (the branches those seeds reach). Reachability keeps its seeded IK either way.
"""

from __future__ import annotations

import math
import threading
from collections.abc import Callable, Iterator, Sequence
from dataclasses import dataclass
from typing import cast

import numpy as np
from numpy.typing import NDArray
from scipy.spatial import KDTree

from devices.angles import wrap_angle
from devices.arm.closed_form import closed_form
from devices.arm.collision import CollisionWorld
from devices.arm.ik import every_branch, fit_limits_toward, fixed_seeds, solve_ik
from devices.arm.model import ArmModel
from planner.types import Pose

_SeedLibrary = tuple[list[NDArray[np.float64]], KDTree, NDArray[np.float64], NDArray[np.float64], float]
_LIBRARIES: dict[tuple[int, tuple[float, float]], tuple[ArmModel, _SeedLibrary]] = {}
"""(id of the arm model, plate) -> (the model, its seed library): the arm is kept so its id is not reused."""
_LIBRARIES_LOCK = threading.Lock()
_Anchors = dict[tuple[int, ...], NDArray[np.float64] | None]
_ANCHORS: dict[tuple[int, tuple[float, float], bytes], tuple[ArmModel, _Anchors]] = {}
"""(id of the arm model, plate, home) -> (the model, the IK anchors its cells solved): shared like the library."""
_MISSING = object()

LIBRARY_SIZE = 600
"""Configurations sampled at start-up whose camera poses seed IK for nearby targets."""
ORIENTATION_WEIGHT = 0.2
"""Metres per unit of camera-axis difference in the seed library's pose distance."""
ANCHOR_STEP = 0.03
"""Grid step of the IK anchors' positions, metres."""
ANCHOR_AXIS_STEP = 0.1
"""Grid step of the IK anchors' camera axes (per component of the unit z and x axes)."""
CACHE_SIZE = 20_000
"""IK results kept (cleared when full)."""
ATTEMPT_CACHE_SIZE = 50_000
"""Reachability attempts (view, plate angle, object box) kept (cleared when full)."""


def rz_matrix(theta: float) -> NDArray[np.float64]:
    c, s = math.cos(theta), math.sin(theta)
    return np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])


def turn_matrix(angles: NDArray[np.float64], angles_to: NDArray[np.float64] | None = None) -> NDArray[np.float64]:
    """(A, B) the shorter plate turn (rad, in [0, pi]) from each of the A plate ``angles`` to each of the B
    ``angles_to`` (rad; default ``angles``: (K, K) between every two)."""
    a = np.asarray(angles, dtype=np.float64).reshape(-1)
    b = a if angles_to is None else np.asarray(angles_to, dtype=np.float64).reshape(-1)
    return np.abs(np.remainder(a[:, None] - b[None, :] + math.pi, 2 * math.pi) - math.pi)


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
    return (
        3
        if reason.startswith("turn:")
        else 2
        if reason.startswith("collision")
        else 1
        if reason == "joint_limit"
        else 0
    )


class ArmReach:
    """Reachability and targets of views for one arm in one cell (not thread-safe: one per cell).

    arm: the loaded model. world: its collision world (plate, table, object box). home: (n,) the configuration
    reachability's IK solutions are wrapped towards (joint turns), so they do not depend on the current state.
    turn_while_moving: :attr:`turn_while_moving` (``ArmConfig.turn_while_moving``).
    """

    def __init__(
        self, arm: ArmModel, world: CollisionWorld, home: NDArray[np.float64], *, turn_while_moving: bool = False
    ) -> None:
        self.arm = arm
        self.home = np.asarray(home, dtype=np.float64)
        self.world = world
        self._data = arm.model.createData()
        mount = arm.T_base_mount.translation
        self.arm_azimuth = math.atan2(mount[1], mount[0])
        self._offsets = [math.radians(o) for o in arm.config.plate_offsets_deg]
        self._aims = [self.arm_azimuth + o for o in self._offsets]
        """Per plate offset, the azimuth (rad) a view's own azimuth is turned to (:meth:`plate_angles`)."""
        n = len(self._offsets)
        self._orders = [[k, *(i for i in range(n) if i != k)] for k in range(n)]
        """Per last serving offset k, the order :meth:`reachability` tries the offsets in (k first)."""
        self._box_seen: tuple[object, bytes] = (None, b"")
        self._wrist_joint = int(arm.model.frames[arm.camera_frame].parentJoint)
        self._library, self._library_tree, self._wrist_in_camera, self._root, self.reach = self._seed_library()
        self._cache: dict[tuple[object, ...], tuple[list[NDArray[np.float64]], str | None]] = {}
        self._anchors = self._shared_anchors()
        self._closed_form = closed_form(arm)
        """Every IK branch of a move in closed form (a UR-type arm), else None: damped least squares from seeds."""
        self._attempts: dict[tuple[bytes, bytes, float, bytes], tuple[NDArray[np.float64], Pose] | str] = {}
        self._last_offset = 0
        self._velocity: list[float] = arm.velocity.tolist()
        self._acceleration: list[float] = arm.acceleration.tolist()
        self.use_attempt_cache = True
        """False: every reachability attempt is computed afresh (the reference the cache is tested against)."""
        self.turn_while_moving = bool(turn_while_moving)
        """Move estimates take the plate's turn and the arm's trajectory as running together (their longer) when
        both ends of the move stand clear of the turning object (:meth:`sweep_free`), as the cell then moves
        (``ArmConfig.turn_while_moving``); else one after the other."""
        self._sweep: dict[tuple[bytes, bytes], bool] = {}

    # ------------------------------------------------------------------ helpers

    def _seed_library(self) -> _SeedLibrary:
        """The seed library, its pose tree and the reach bound: a pure function of the (cached, never changed) arm
        model and the world's fixed obstacles (plate, table; the library is checked at plate angle 0 before any
        object box is set), so computed once per process for each (arm, plate) and shared, read only, by the
        sessions' cells (a world that already holds an object box gets its own)."""
        key = (id(self.arm), self.world.plate)
        shared = self.world.box is None
        with _LIBRARIES_LOCK:
            hit = _LIBRARIES.get(key) if shared else None
        if hit is not None and hit[0] is self.arm:
            return hit[1]
        library = [q for q in fixed_seeds(self.arm, LIBRARY_SIZE, seed=1) if self.world.collision(q, 0.0) is None]
        tree = KDTree(np.array([self._feature(self.arm.camera_pose(q, self._data)) for q in library]))
        self._library = library
        built: _SeedLibrary = (library, tree, *self._reach_bound())
        if shared:
            with _LIBRARIES_LOCK:
                if len(_LIBRARIES) >= 8:
                    _LIBRARIES.clear()
                _LIBRARIES[key] = (self.arm, built)
        return built

    def _shared_anchors(self) -> _Anchors:
        """The IK anchors (:meth:`_anchor`) of every cell of this (arm, plate, home) in the process, shared as the
        seed library is: each anchor is a pure function of its grid cell, the arm model, the library and home, so a
        cell that plans views an earlier cell of the process planned (a bench's runs of one model and placement, a
        server's sessions of one object, their moves) finds their anchors: such a plan's CPU about halves (0.13 ->
        0.07 s, mug, the tests' small config; the same plans). A session's worker process starts with none (anchors
        of a nominal hemisphere solved in the forkserver were tried: no plan used one). A world that already holds
        an object box has a library of its own, and anchors of its own."""
        if self.world.box is not None:
            return {}
        key = (id(self.arm), self.world.plate, self.home.tobytes())
        with _LIBRARIES_LOCK:
            hit = _ANCHORS.get(key)
            if hit is not None and hit[0] is self.arm:
                return hit[1]
            anchors: _Anchors = {}
            if len(_ANCHORS) >= 8:
                _ANCHORS.clear()
            _ANCHORS[key] = (self.arm, anchors)
        return anchors

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
        azimuth = self._azimuth(T_table_camera)
        return [self._plate_angle(i, azimuth, current_angle) for i in range(len(self._offsets))]

    @staticmethod
    def _azimuth(T_table_camera: Pose) -> float | None:
        """The view's azimuth about the plate's axis (rad), None on the axis itself."""
        x, y = T_table_camera.translation[:2]
        return None if math.hypot(x, y) < 1e-9 else math.atan2(y, x)

    def _plate_angle(self, i: int, azimuth: float | None, current_angle: float) -> float:
        """Plate angle (rad) of offset ``i`` for a view at ``azimuth`` (:meth:`_azimuth`; on the axis: the current
        angle plus the offset)."""
        if azimuth is None:
            return wrap_angle(current_angle + self._offsets[i])
        return wrap_angle(self._aims[i] - azimuth)

    def turn_seconds(self, angle_from: float, angle_to: float) -> float:
        """Seconds the turntable takes from ``angle_from`` to ``angle_to`` (rad) the short way at its speed: the
        turn of every move's estimate (:meth:`move_estimate`, :meth:`move_seconds`) and so a lower bound of it."""
        return abs(wrap_angle(angle_to - angle_from)) / math.radians(self.arm.config.turntable_speed_deg)

    def move_estimate(
        self, q_from: NDArray[np.float64], q_to: NDArray[np.float64], angle_from: float, angle_to: float
    ) -> float:
        """Seconds of a rest-to-rest move: turntable at its speed, then the slowest joint (trapezoid profile).
        Plain floats (it runs for every candidate of every plan); :meth:`seconds_between` is the same for many
        pairs."""
        turn = self.turn_seconds(angle_from, angle_to)
        slowest = 0.0
        for a_from, a_to, v, a in zip(q_from.tolist(), q_to.tolist(), self._velocity, self._acceleration, strict=True):
            dq = abs(a_to - a_from)
            slowest = max(slowest, dq / v + v / a if dq > v * v / a else 2.0 * math.sqrt(dq / a))
        return turn + slowest

    def sweep_free(self, q: NDArray[np.float64]) -> bool:
        """:meth:`CollisionWorld.sweep_free` of (n,) ``q`` with the current object box, cached per (q, box): the arm
        standing at ``q`` is clear of the cylinder the padded box sweeps at every plate angle."""
        q = np.asarray(q, dtype=np.float64)
        key = (q.tobytes(), self._box_key())
        hit = self._sweep.get(key)
        if hit is None:
            if len(self._sweep) >= CACHE_SIZE:
                self._sweep.clear()
            hit = self._sweep[key] = self.world.sweep_free(q)
        return hit

    def move_seconds(
        self, q_from: NDArray[np.float64], q_to: NDArray[np.float64], angle_from: float, angle_to: float
    ) -> float:
        """Seconds of the move as the cell makes it: :meth:`move_estimate` (turn, then arm), or with
        :attr:`turn_while_moving` and both ends clear of the turning object (:meth:`sweep_free`) the longer of the
        plate's turn and the arm's trajectory (they run together)."""
        sequential = self.move_estimate(q_from, q_to, angle_from, angle_to)
        if not self.turn_while_moving or not (self.sweep_free(q_from) and self.sweep_free(q_to)):
            return sequential
        turn = self.turn_seconds(angle_from, angle_to)
        return max(turn, sequential - turn)

    def seconds_between(
        self,
        q_from: NDArray[np.float64],
        angles_from: NDArray[np.float64],
        q_to: NDArray[np.float64],
        angles_to: NDArray[np.float64],
    ) -> NDArray[np.float64]:
        """(A, B) :meth:`move_seconds` from each of A states to each of B states: q_from (A, n), angles_from (A,),
        q_to (B, n), angles_to (B,) (joints in radians, plate angles in radians)."""
        q_from = np.asarray(q_from, dtype=np.float64).reshape(-1, self.arm.nq)
        q_to = np.asarray(q_to, dtype=np.float64).reshape(-1, self.arm.nq)
        turn = turn_matrix(angles_from, angles_to) / math.radians(self.arm.config.turntable_speed_deg)
        dq = np.abs(q_from[:, None, :] - q_to[None, :, :])
        v, a = self.arm.velocity, self.arm.acceleration
        arm = np.where(dq > v * v / a, dq / v + v / a, 2.0 * np.sqrt(dq / a)).max(axis=2, initial=0.0)
        if not self.turn_while_moving:
            return turn + arm
        clear_from = np.array([self.sweep_free(q) for q in q_from], dtype=bool)
        clear_to = np.array([self.sweep_free(q) for q in q_to], dtype=bool)
        together = clear_from[:, None] & clear_to[None, :]
        return np.where(together, np.maximum(turn, arm), turn + arm)

    def _box_key(self) -> bytes:
        """The padded object box as bytes (b"" without one), computed once per box the world is given."""
        box = self.world.box
        seen, key = self._box_seen
        if box is not seen:
            key = b"" if box is None else box[0].tobytes() + box[1].tobytes()
            self._box_seen = (box, key)
        return key

    def _ik(
        self, T_base_camera: Pose, reference: NDArray[np.float64], *, first: bool
    ) -> tuple[list[NDArray[np.float64]], str | None]:
        """IK of one pose. first=True (reachability): a pure function of the pose (seeds: its anchor and the
        library; limits fitted towards home), so a replay of the same plans gets the same answers whatever was
        asked before. first=False (a move): every branch, the current configuration ``reference`` first."""
        key = (T_base_camera.translation.tobytes(), T_base_camera.rotation.tobytes(), first)
        if not first:
            key += (np.asarray(reference).tobytes(),)
        hit = self._cache.get(key)
        if hit is not None:
            return hit
        if not first and self._closed_form is not None:
            result = every_branch(self.arm, self._closed_form, T_base_camera, reference)
        else:
            result = self._seeded_ik(T_base_camera, reference, first=first)
        if len(self._cache) >= CACHE_SIZE:
            self._cache.clear()
        self._cache[key] = result
        return result

    def _seeded_ik(
        self, T_base_camera: Pose, reference: NDArray[np.float64], *, first: bool
    ) -> tuple[list[NDArray[np.float64]], str | None]:
        """:meth:`_ik` by damped least squares from seeds: the current configuration (a move), the pose's anchor,
        then the library."""

        def seeds() -> Iterator[NDArray[np.float64]]:  # lazily: the library is searched only if needed
            if not first:
                yield np.asarray(reference, dtype=np.float64)
            anchor = self._anchor(T_base_camera)
            if anchor is not None:
                yield anchor
            k = self.arm.config.ik_seeds if first else 2 * self.arm.config.ik_seeds
            if first and anchor is None:
                k = 1  # the cell's centre is out of reach: one more try (a cell on the workspace's edge), not all
            yield from self._library_seeds(T_base_camera, k)

        return solve_ik(self.arm, T_base_camera, seeds(), self.home if first else reference, self._data, first=first)

    def _library_seeds(self, T_base_camera: Pose, k: int) -> list[NDArray[np.float64]]:
        _, idx = self._library_tree.query(self._feature(T_base_camera), k=min(k, len(self._library)))
        return [self._library[i] for i in np.atleast_1d(idx)]

    def _anchor(self, T_base_camera: Pose) -> NDArray[np.float64] | None:
        """The IK solution of the centre of the pose's grid cell (``ANCHOR_STEP`` metres, ``ANCHOR_AXIS_STEP`` per
        camera-axis component), computed once per cell: a seed a few iterations from any pose of the cell."""
        p = np.round(T_base_camera.translation / ANCHOR_STEP)
        z = np.round(T_base_camera.rotation[:, 2] / ANCHOR_AXIS_STEP)
        x = np.round(T_base_camera.rotation[:, 0] / ANCHOR_AXIS_STEP)
        key = (*p.astype(int), *z.astype(int), *x.astype(int))
        known = self._anchors.get(key, _MISSING)  # one lookup: another cell's thread may clear the shared dict
        if known is not _MISSING:
            return cast("NDArray[np.float64] | None", known)
        z_axis = z / max(float(np.linalg.norm(z)), 1e-12)
        x_axis = x - (x @ z_axis) * z_axis
        anchor: NDArray[np.float64] | None = None
        if float(np.linalg.norm(x_axis)) > 1e-6 and float(np.linalg.norm(z)) > 1e-6:
            x_axis /= np.linalg.norm(x_axis)
            centre = Pose(np.column_stack([x_axis, np.cross(z_axis, x_axis), z_axis]), p * ANCHOR_STEP)
            if not self.out_of_reach(centre):
                seeds = self._library_seeds(centre, self.arm.config.ik_seeds)
                solutions, _ = solve_ik(self.arm, centre, seeds, self.home, self._data, first=True)
                anchor = solutions[0] if solutions else None
        if len(self._anchors) >= CACHE_SIZE:
            self._anchors.clear()
        self._anchors[key] = anchor
        return anchor

    # ------------------------------------------------------------------ queries

    def reachability(
        self, T_table_camera: Pose, q_current: NDArray[np.float64], angle_current: float
    ) -> tuple[ArmTarget | None, str | None]:
        """A plate angle whose IK solution is inside the limits and free (the first found; the offset that
        served the previous query is tried first), or (None, reason)."""
        found = self._first_free(T_table_camera, q_current, angle_current)
        if isinstance(found, str):
            return None, found
        angle, q, T_base_camera = found
        return ArmTarget(angle, q, T_base_camera, self.move_estimate(q_current, q, angle_current, angle)), None

    def reachable_angle(
        self, T_table_camera: Pose, q_current: NDArray[np.float64], angle_current: float
    ) -> tuple[float | None, str | None]:
        """:meth:`reachability`'s plate angle alone (no move estimate: the planner's 400 questions a plan), or
        (None, reason)."""
        found = self._first_free(T_table_camera, q_current, angle_current)
        return (None, found) if isinstance(found, str) else (found[0], None)

    def _first_free(
        self, T_table_camera: Pose, q_current: NDArray[np.float64], angle_current: float
    ) -> tuple[float, NDArray[np.float64], Pose] | str:
        """(plate angle, q (n,), T_base_camera) of the first plate angle with a free target, the offset that served
        the previous query first (neighbours behave alike; the verdict does not depend on the order), or the worst
        reason of all. Plate angles are computed as they are tried."""
        worst = "no_ik"
        azimuth = self._azimuth(T_table_camera)
        view = (T_table_camera.translation.tobytes(), T_table_camera.rotation.tobytes())
        for i in self._orders[self._last_offset]:
            angle = self._plate_angle(i, azimuth, angle_current)
            hit = self._cached_attempt(T_table_camera, angle, q_current, angle_current, view)
            if not isinstance(hit, str):
                self._last_offset = i
                return (angle, *hit)
            if _severity(hit) > _severity(worst):
                worst = hit
        return worst

    def best_target(
        self,
        T_table_camera: Pose,
        q_current: NDArray[np.float64],
        angle_current: float,
        turn_check: Callable[[float], str | None] | None = None,
        then: Sequence[Pose] = (),
    ) -> tuple[ArmTarget | None, str | None]:
        """Among every plate angle and IK branch, the free target with the shortest estimated move (the first of
        the tried angles, :meth:`plate_angles`, among equals).
        turn_check: plate angle -> why the plate cannot turn there (None: it can); angles it refuses are skipped.

        The angles are tried nearest turn first, and once a target is found an angle whose turn alone takes longer
        than that target's move is not tried: the plate's turn is part of every move's estimate (turn then arm,
        or the longer of the two), so no branch there can be shorter. The answer is the one every angle's IK would
        give (the shortest, ties to the earlier angle), with less IK: measured on the UR5 over 100 views of the
        default hemisphere from 6 arm states, 20.9 -> 14.0 ms a call (turn then arm), 17.0 -> 6.8 ms (turning while
        moving), the same answers (tests/devices/test_arm_reach.py).

        then: the views (``T_table_camera`` each) the move after this one is expected to go to (the tour's ring:
        ``PlanResult.then_poses``): the target is instead the one whose move plus the quickest move on to one of them
        is shortest (:meth:`_best_chained`; without a free target among them, as without ``then``)."""
        if then:
            chained = self._best_chained(T_table_camera, q_current, angle_current, turn_check, then)
            if chained is not None:
                return chained
        best: ArmTarget | None = None
        best_order = -1
        worst = "no_ik"
        angles = self.plate_angles(T_table_camera, angle_current)
        turns = [self.turn_seconds(angle_current, angle) for angle in angles]
        for order in sorted(range(len(angles)), key=lambda i: (turns[i], i)):
            if best is not None and turns[order] > best.move_estimate:
                break  # this turn, and every later one, outlasts the best move
            angle = angles[order]
            target, reason = self._attempt(T_table_camera, angle, q_current, angle_current, first=False)
            if target is not None and turn_check is not None:
                blocked = turn_check(target.angle)
                if blocked is not None:
                    target, reason = None, blocked
            if target is None:
                assert reason is not None
                if _severity(reason) > _severity(worst):
                    worst = reason
            else:
                if self.turn_while_moving:  # the move as the cell makes it (turn and arm together when clear)
                    seconds = self.move_seconds(q_current, target.q, angle_current, target.angle)
                    target = ArmTarget(target.angle, target.q, target.T_base_camera, seconds)
                if best is None or (target.move_estimate, order) < (best.move_estimate, best_order):
                    best, best_order = target, order
        return (best, None) if best is not None else (None, worst)

    def _branches(
        self, T_table_camera: Pose, angle: float, reference: NDArray[np.float64], *, first: bool
    ) -> tuple[Pose, list[NDArray[np.float64]], str | None]:
        """(T_base_camera, IK solutions, why none) of a view at plate ``angle`` (:meth:`_ik`; ``no_ik`` at once when
        the pose is out of the arm's reach)."""
        R = rz_matrix(angle)
        T_base_camera = Pose.trusted(R @ T_table_camera.rotation, R @ T_table_camera.translation)
        if self.out_of_reach(T_base_camera):
            return T_base_camera, [], "no_ik"
        return T_base_camera, *self._ik(T_base_camera, reference, first=first)

    def _free_branches(
        self, T_table_camera: Pose, angle: float, reference: NDArray[np.float64]
    ) -> tuple[list[NDArray[np.float64]], str | None]:
        """Every free IK branch (n,) of a view at plate ``angle`` (nearest ``reference`` first), and why there is
        none (``no_ik``, ``joint_limit`` or the first branch's collision)."""
        _, solutions, reason = self._branches(T_table_camera, angle, reference, first=False)
        free: list[NDArray[np.float64]] = []
        for q in solutions:
            hit = self.world.collision(q, angle)
            if hit is None:
                free.append(q)
            elif reason is None:
                reason = hit
        return free, None if free else reason or "no_ik"

    def _best_chained(
        self,
        T_table_camera: Pose,
        q_current: NDArray[np.float64],
        angle_current: float,
        turn_check: Callable[[float], str | None] | None,
        then: Sequence[Pose],
    ) -> tuple[ArmTarget | None, str | None] | None:
        """:meth:`best_target` with a look-ahead: among every plate angle and free IK branch of the view, the target
        with the shortest move from the current state plus the quickest move from it on to any free target (every
        plate angle and branch, each turned towards the target's joints) of the views ``then``. The angles are tried
        nearest turn first and stop where the turn alone outlasts the best sum. ArmTarget.move_estimate is the
        move's own estimate. None when no view of ``then`` has a free target (the caller then chooses without it)."""
        q_next: list[NDArray[np.float64]] = []
        angle_next: list[float] = []
        for pose in then:
            for angle in self.plate_angles(pose, angle_current):
                free, _ = self._free_branches(pose, angle, self.home)
                q_next += free
                angle_next += [angle] * len(free)
        if not q_next:
            return None
        qb, ab = np.stack(q_next), np.array(angle_next)
        best: ArmTarget | None = None
        best_total = math.inf
        worst = "no_ik"
        angles = self.plate_angles(T_table_camera, angle_current)
        turns = [self.turn_seconds(angle_current, angle) for angle in angles]
        here, lower, upper = np.array([angle_current]), self.arm.lower, self.arm.upper
        for order in sorted(range(len(angles)), key=lambda i: (turns[i], i)):
            if turns[order] > best_total:
                break  # this turn, and every later one, outlasts the best move and its next one together
            angle = angles[order]
            free, reason = self._free_branches(T_table_camera, angle, q_current)
            if free and turn_check is not None:
                blocked = turn_check(angle)
                if blocked is not None:
                    free, reason = [], blocked
            if not free:
                if reason is not None and _severity(reason) > _severity(worst):
                    worst = reason
                continue
            qa = np.stack(free)
            first = self.seconds_between(q_current[None, :], here, qa, np.full(len(qa), angle))[0]  # (A,)
            onward = np.array(
                [
                    self.seconds_between(
                        q[None, :], np.array([angle]), fit_limits_toward(qb, q, lower, upper), ab
                    ).min()
                    for q in qa
                ]
            )  # (A,) the quickest next move from each branch
            total = first + onward
            i = int(np.argmin(total))
            if total[i] < best_total - 1e-9:  # the earlier angle (and the nearer branch) among equals
                best_total = float(total[i])
                best = ArmTarget(angle, free[i], self.arm.camera_pose(free[i], self._data), float(first[i]))
        return (best, None) if best is not None else (None, worst)

    def _cached_attempt(
        self,
        T_table_camera: Pose,
        angle: float,
        q_current: NDArray[np.float64],
        angle_current: float,
        view: tuple[bytes, bytes] | None = None,
    ) -> tuple[NDArray[np.float64], Pose] | str:
        """The reachability attempt at plate ``angle`` ((q (n,), T_base_camera) or why none), from the cache when
        :attr:`use_attempt_cache` (computed and kept on a miss). view: the view's key bytes (translation,
        rotation), when the caller has them."""
        key = self._attempt_key(T_table_camera, angle, view) if self.use_attempt_cache else None
        if key is not None:
            hit = self._attempts.get(key)
            if hit is not None:
                return hit
        target, reason = self._attempt(T_table_camera, angle, q_current, angle_current, first=True)
        found = (target.q, target.T_base_camera) if target is not None else str(reason)
        if key is not None:
            if len(self._attempts) >= ATTEMPT_CACHE_SIZE:
                self._attempts.clear()
            self._attempts[key] = found
        return found

    def _attempt_key(
        self, T_table_camera: Pose, angle: float, view: tuple[bytes, bytes] | None = None
    ) -> tuple[bytes, bytes, float, bytes]:
        """The attempt cache's key: the view's bytes (``view`` when the caller has them), the plate angle, the box."""
        if view is None:
            view = (T_table_camera.translation.tobytes(), T_table_camera.rotation.tobytes())
        return view[0], view[1], float(angle), self._box_key()

    def free_targets(
        self, T_table_camera: Pose, q_current: NDArray[np.float64], angle_current: float
    ) -> list[tuple[NDArray[np.float64], float]]:
        """(q (n,), plate angle) of the reachability attempt at each plate angle the view is tried at
        (:meth:`plate_angles`) that found a free target: the same state-independent, cached attempts as
        :meth:`reachability`, every plate angle instead of the first that serves (a few ms of IK per view when
        cold, microseconds when cached). Empty when the view is unreachable."""
        found: list[tuple[NDArray[np.float64], float]] = []
        for angle in self.plate_angles(T_table_camera, angle_current):
            hit = self._cached_attempt(T_table_camera, angle, q_current, angle_current)
            if not isinstance(hit, str):
                found.append((hit[0], angle))
        return found

    def _attempt(
        self, T_table_camera: Pose, angle: float, q_current: NDArray[np.float64], angle_current: float, *, first: bool
    ) -> tuple[ArmTarget | None, str | None]:
        T_base_camera, solutions, reason = self._branches(T_table_camera, angle, q_current, first=first)
        if not solutions:
            return None, reason
        if not first:  # a move: the shortest free branch, collisions checked nearest move first
            return self._nearest_free(solutions, angle, q_current, angle_current)
        collision = self.world.collision(solutions[0], angle)
        if collision is not None:
            # another branch may be free: the library's seeds, keeping only a free solution (state-independent)
            seeds = self._library_seeds(T_base_camera, self.arm.config.ik_seeds)

            def free(q: NDArray[np.float64]) -> bool:
                return self.world.collision(q, angle) is None

            solutions, _ = solve_ik(self.arm, T_base_camera, seeds, self.home, self._data, first=True, accept=free)
        for q in solutions:  # reachability: the first free solution
            hit = self.world.collision(q, angle)
            if hit is not None:
                collision = collision or hit
                continue
            estimate = self.move_estimate(q_current, q, angle_current, angle)
            return ArmTarget(angle, q, self.arm.camera_pose(q, self._data), estimate), None
        return None, collision

    def _nearest_free(
        self, solutions: list[NDArray[np.float64]], angle: float, q_current: NDArray[np.float64], angle_current: float
    ) -> tuple[ArmTarget | None, str | None]:
        """Of a move's IK branches (non-empty, sorted by joint distance), the free one with the shortest move estimate
        (the earlier of equals), or the first one's collision when none is free: what checking every branch gives,
        with the collision checks (about 40 us each) stopped at the first free branch in the order of the move."""
        estimates = [self.move_estimate(q_current, q, angle_current, angle) for q in solutions]
        hits: dict[int, str] = {}
        for i in sorted(range(len(solutions)), key=lambda i: (estimates[i], i)):
            hit = self.world.collision(solutions[i], angle)
            if hit is None:
                q = solutions[i]
                return ArmTarget(angle, q, self.arm.camera_pose(q, self._data), estimates[i]), None
            hits[i] = hit
        return None, hits[min(hits)]
