"""Inverse kinematics of the camera pose: Pinocchio's damped least squares from several seeds, joint limits after.

A solution must put the camera (``ArmModel.camera_frame``) at ``T_base_camera`` within ``ArmConfig.ik_tolerance``
(metres; radians x 10) and lie inside the joint limits. Revolute joints are wrapped by whole turns to the
solution nearest the reference configuration that fits the limits. Failure reasons: ``no_ik`` (no seed
converged: the pose is out of the arm's workspace) or ``joint_limit`` (it converged, but only outside the limits).
"""

from __future__ import annotations

import math
from collections.abc import Callable, Iterable
from typing import Any

import numpy as np
from numpy.typing import NDArray

from devices.arm.closed_form import ClosedFormIK
from devices.arm.model import ArmModel
from planner.types import Pose

DAMPING = 1e-6
"""Damping of the least-squares step (Pinocchio's IK example uses 1e-6)."""
STALL_WINDOW = 6
"""Iterations over which the error must shrink ..."""
STALL_RATIO = 0.9
"""... to at most this fraction of what it was, or the seed is given up."""
MAX_STEP = 0.5
"""Largest joint step of one iteration, radians (keeps the iteration from jumping between branches)."""
NULL_GAIN = 0.5
"""A redundant arm (more than 6 joints): gain of the secondary task in the Jacobian's null space, which pulls the
joints towards the reference configuration (the current joints on a move) ..."""
LIMIT_GAIN = 0.01
"""... and away from the joint limits (the gradient of ``sum(((q - mid) / range)^2)``, strongest near a limit)."""
NULL_ITERATIONS = 10
"""A redundant arm: iterations of the secondary task after the pose is reached (the self-motion that brings the
solution nearer the reference and away from the limits while the camera stays put)."""
SELF_MOTION_DONE = 1e-3
"""Radians: a self-motion step smaller than this (every joint) ends it."""
LIMIT_MARGIN = 0.05
"""Fraction of a joint's range kept clear of each limit by the limit term (where it can be, for a redundant arm)."""


def dls(
    arm: ArmModel,
    data: Any,
    M_target: Any,
    q0: NDArray[np.float64],
    iterations: int,
    tolerance: float,
    reference: NDArray[np.float64] | None = None,
) -> NDArray[np.float64] | None:
    """(n,) a configuration putting the camera at ``M_target`` (``pinocchio.SE3``, base frame) from seed ``q0``,
    or None if damped least squares does not converge in ``iterations`` steps. No joint limits here.

    A redundant arm (more than 6 joints) uses its redundancy: once the pose is reached, up to
    :data:`NULL_ITERATIONS` steps of self-motion follow, in the Jacobian's null space (the camera stays put): a pull
    towards ``reference`` (``q0`` when None) and a push away from the joint limits (:data:`NULL_GAIN`,
    :data:`LIMIT_GAIN`), each followed by the correction of the pose (the last configuration within the tolerance
    is returned)."""
    import pinocchio as pin  # pyright: ignore[reportMissingImports]  (under cmeel.prefix)

    model, frame = arm.model, arm.camera_frame
    q = np.array(q0, dtype=np.float64)
    eye6 = np.eye(6)
    redundant = model.nv > 6
    ref = np.array(q0 if reference is None else reference, dtype=np.float64)
    mid, span = 0.5 * (arm.lower + arm.upper), np.maximum(arm.upper - arm.lower, 1e-6)
    history: list[float] = []
    solved: NDArray[np.float64] | None = None
    extra = 0
    for i in range(iterations + 2 * NULL_ITERATIONS):
        pin.forwardKinematics(model, data, q)
        M = pin.updateFramePlacement(model, data, frame)
        iMd = M.actInv(M_target)
        err = pin.log6(iMd).vector
        position, rotation = math.sqrt(err[:3] @ err[:3]), math.sqrt(err[3:] @ err[3:])
        on_pose = position < tolerance and rotation < 10 * tolerance
        if on_pose:
            if not redundant or extra >= NULL_ITERATIONS:
                return q
            solved = q
            extra += 1
        elif solved is not None:
            pass  # the self-motion left the pose by its linearisation error: this step corrects it
        elif i >= iterations:
            return None
        else:
            history.append(position + 0.1 * rotation)
            if i >= STALL_WINDOW and history[-1] > STALL_RATIO * history[-1 - STALL_WINDOW]:
                return None  # stalled: out of reach from this seed (a singular or limit-bound configuration)
        pin.computeJointJacobians(model, data)  # from the placements just computed (no second FK)
        J = -pin.Jlog6(iMd.inverse()) @ pin.getFrameJacobian(model, data, frame, pin.LOCAL)
        JJt = J @ J.T + DAMPING * eye6
        v = -J.T @ np.linalg.solve(JJt, err)
        if on_pose:  # self-motion: the secondary task projected into the null space
            centred = (q - mid) / span
            z = NULL_GAIN * (ref - q) - LIMIT_GAIN * centred / np.maximum(0.5 - np.abs(centred), LIMIT_MARGIN) ** 2
            step = z - J.T @ np.linalg.solve(JJt, J @ z)
            if float(np.max(np.abs(step))) < SELF_MOTION_DONE:
                return q
            v = v + step
        largest = float(np.max(np.abs(v)))
        if largest > MAX_STEP:
            v *= MAX_STEP / largest
        q = q + v
    return solved


def fit_limits(
    q: NDArray[np.float64], reference: NDArray[np.float64], lower: NDArray[np.float64], upper: NDArray[np.float64]
) -> NDArray[np.float64] | None:
    """(n,) ``q`` with each joint moved by whole turns to lie in [lower, upper], nearest ``reference``; None if a
    joint fits no turn."""
    fitted, fits = _turned(q, reference, lower, upper)
    return fitted if bool(np.all(fits)) else None


def fit_limits_toward(
    q: NDArray[np.float64], reference: NDArray[np.float64], lower: NDArray[np.float64], upper: NDArray[np.float64]
) -> NDArray[np.float64]:
    """(M, n) the configurations ``q`` (M, n), each already inside [lower, upper], with every joint moved by whole
    turns to the turn inside the limits nearest ``reference`` (n,): :func:`fit_limits` of many at once, towards
    another reference (a branch solved towards one configuration, measured from another)."""
    return _turned(q, reference, lower, upper)[0]


def _turned(
    q: NDArray[np.float64], reference: NDArray[np.float64], lower: NDArray[np.float64], upper: NDArray[np.float64]
) -> tuple[NDArray[np.float64], NDArray[np.bool_]]:
    """(q turned, fits), both shaped as ``q`` (..., n): each joint moved by the whole turns, among those that put it in
    [lower, upper], nearest ``reference``, and whether any turn does (where none does, the value is meaningless)."""
    two_pi = 2 * math.pi
    k_lo = np.ceil((lower - q) / two_pi - 1e-12)
    k_hi = np.floor((upper - q) / two_pi + 1e-12)
    k = np.minimum(np.maximum(np.round((reference - q) / two_pi), k_lo), k_hi)
    return np.minimum(np.maximum(q + k * two_pi, lower), upper), k_lo <= k_hi


def solve_ik(
    arm: ArmModel,
    T_base_camera: Pose,
    seeds: Iterable[NDArray[np.float64]],
    reference: NDArray[np.float64],
    data: Any | None = None,
    *,
    first: bool = True,
    accept: Callable[[NDArray[np.float64]], bool] | None = None,
) -> tuple[list[NDArray[np.float64]], str | None]:
    """Solutions (each (n,), inside the limits) for ``T_base_camera`` from ``seeds`` (any iterable: a generator
    computes the later seeds only when the earlier ones failed), and the reason when none.

    first: stop at the first solution (a reachability test); else try every seed and return the distinct
    solutions sorted by joint distance from ``reference`` (the current configuration).
    accept: solutions it refuses (e.g. in collision) are dropped and the next seed is tried.
    """
    import pinocchio as pin  # pyright: ignore[reportMissingImports]  (under cmeel.prefix)

    cfg = arm.config
    data = data if data is not None else arm.model.createData()
    M_target = pin.SE3(T_base_camera.rotation, T_base_camera.translation)
    solutions: list[NDArray[np.float64]] = []
    converged = False
    for seed in seeds:
        q = dls(arm, data, M_target, seed, cfg.ik_iterations, cfg.ik_tolerance, reference)
        if q is None:
            continue
        converged = True
        fitted = _fitted_new(arm, q, reference, solutions)
        if fitted is None:
            continue
        if accept is not None and not accept(fitted):
            continue
        solutions.append(fitted)
        if first:
            break
    if not solutions:
        return [], "joint_limit" if converged else "no_ik"
    return _nearest_first(solutions, reference), None


def every_branch(
    arm: ArmModel, solver: ClosedFormIK, T_base_camera: Pose, reference: NDArray[np.float64]
) -> tuple[list[NDArray[np.float64]], str | None]:
    """:func:`solve_ik` with ``first=False`` in closed form (a UR-type arm, :mod:`devices.arm.closed_form`): every
    branch of the pose, each turned by whole turns to the limits nearest ``reference``, distinct, sorted by joint
    distance from it; the reason when none (``no_ik`` out of reach, ``joint_limit`` every branch outside)."""
    found = solver.solve(T_base_camera, reference)
    if not found:
        return [], "no_ik"
    solutions: list[NDArray[np.float64]] = []
    for q in found:
        fitted = _fitted_new(arm, q, reference, solutions)
        if fitted is not None:
            solutions.append(fitted)
    if not solutions:
        return [], "joint_limit"
    return _nearest_first(solutions, reference), None


SAME_SOLUTION = 1e-3
"""Radians: two solutions whose joints all differ by less than this are one."""


def _fitted_new(
    arm: ArmModel, q: NDArray[np.float64], reference: NDArray[np.float64], solutions: list[NDArray[np.float64]]
) -> NDArray[np.float64] | None:
    """``q`` turned into the limits nearest ``reference`` (:func:`fit_limits`), or None when it fits no turn or is
    already among ``solutions``: the step :func:`solve_ik` and :func:`every_branch` share."""
    fitted = fit_limits(q, reference, arm.lower, arm.upper)
    if fitted is None or any(np.max(np.abs(fitted - s)) < SAME_SOLUTION for s in solutions):
        return None
    return fitted


def _nearest_first(solutions: list[NDArray[np.float64]], reference: NDArray[np.float64]) -> list[NDArray[np.float64]]:
    """``solutions`` sorted by joint distance from ``reference`` (stable: the earlier of equals first)."""
    return sorted(solutions, key=lambda s: float(np.linalg.norm(s - reference)))


def fixed_seeds(arm: ArmModel, count: int, seed: int = 0) -> list[NDArray[np.float64]]:
    """``count`` spread configurations inside the limits (deterministic), the generic IK seeds of any URDF."""
    rng = np.random.default_rng(seed)
    lo = np.maximum(arm.lower, -math.pi)
    hi = np.minimum(arm.upper, math.pi)
    return [rng.uniform(lo, hi) for _ in range(count)]
