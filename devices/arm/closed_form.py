"""Every inverse-kinematics branch of a UR-type arm in closed form (product of exponentials, no iteration).

A six-joint revolute chain is *UR-type* when the axes of joints 2, 3 and 4 are parallel, joint 1's axis is
perpendicular to them, and the axes of joints 5 and 6 meet in a point (the wrist point): the UR3/5/10/16 and
their e-series. For such a chain a camera pose has at most eight solutions (shoulder left / right x wrist up /
down x elbow up / down), each found by a sequence of one-angle subproblems (Paden-Kahan):

1. joint 1: joints 2-6 leave the wrist point's component along joint 2's axis unchanged (they turn about axes
   parallel to it or through the point), so ``a cos q1 + b sin q1 = c``: two shoulders;
2. joint 5: joints 2-4 leave the component of joint 6's axis along joint 2's axis unchanged: two wrists;
3. joint 6: the same row of the orientation, turned about joint 6's axis (free at the wrist singularity
   ``sin q5 = 0``, where the reference's angle is kept);
4. joints 2-4: a planar three-link arm (parallel axes): the elbow from the distance of joint 4's axis to joint
   2's (two elbows), then joint 2, then joint 4 from their sum.

The chain's axes, points and the camera's pose at the zero configuration are read off the Pinocchio model (its
mount and the camera's flange offset included), so nothing is tied to one URDF's conventions. :func:`closed_form`
checks the geometry and then the solver itself (forward kinematics of spread configurations solved back) and
returns None for any other arm, which keeps the damped least squares of :mod:`devices.arm.ik`.

Angles come out in (-pi, pi]; joint limits and whole turns are the caller's (:func:`devices.arm.ik.fit_limits`).
"""

from __future__ import annotations

import functools
import math
from dataclasses import dataclass, field
from typing import Any

import numpy as np
from numpy.typing import NDArray

from devices.angles import wrap_angle
from devices.arm.model import ArmModel
from planner.types import Pose

GEOMETRY_TOLERANCE = 1e-7
"""Largest deviation (metres, or the sine of an angle) from the UR-type geometry that is still UR-type."""
SELF_CHECK_CONFIGURATIONS = 24
"""Spread configurations whose camera poses the solver must solve back before it is used."""
SINGULAR = 1e-6
"""Below this sine of the angle between joints 2's and 6's axes (joint 5 near 0 or pi) joint 6 is taken as free."""
SOLUTION_TOLERANCE = 1e-6
"""Largest camera position error (metres) of a returned solution, and of the self-check's."""


def _rot(axis: NDArray[np.float64], angle: float) -> NDArray[np.float64]:
    """(3, 3) rotation by ``angle`` about unit ``axis`` (Rodrigues)."""
    x, y, z = axis.tolist()
    c, s = math.cos(angle), math.sin(angle)
    k = 1.0 - c
    return np.array(
        [
            [c + x * x * k, x * y * k - z * s, x * z * k + y * s],
            [y * x * k + z * s, c + y * y * k, y * z * k - x * s],
            [z * x * k - y * s, z * y * k + x * s, c + z * z * k],
        ]
    )


def _screw(axis: NDArray[np.float64], point: NDArray[np.float64], angle: float) -> NDArray[np.float64]:
    """(4, 4) the rigid motion of turning ``angle`` about the line through ``point`` along unit ``axis``."""
    R = _rot(axis, angle)
    out = np.zeros((4, 4))
    out[:3, :3] = R
    out[:3, 3] = point - R @ point
    out[3, 3] = 1.0
    return out


def _cos_sin_equation(a: float, b: float, c: float) -> tuple[list[float], bool]:
    """(the angles q in (-pi, pi] with ``a cos q + b sin q = c``: two, one when tangent, none when |c| > |(a, b)|;
    whether they are exact). A right side within 1e-9 of the reachable range is clamped onto it (a pose on the
    workspace's boundary): not exact, the caller checks the solution."""
    r = math.hypot(a, b)
    if r < 1e-12:
        return [], True
    ratio = c / r
    if abs(ratio) > 1.0 + 1e-9:
        return [], True
    phi, delta = math.atan2(b, a), math.acos(max(-1.0, min(1.0, ratio)))
    if delta < 1e-12:
        return [wrap_angle(phi)], abs(ratio) <= 1.0
    return [wrap_angle(phi + delta), wrap_angle(phi - delta)], True


def _cross(a: NDArray[np.float64], b: NDArray[np.float64]) -> NDArray[np.float64]:
    """a x b of two (3,) vectors (numpy's cross costs ten times more on one pair)."""
    a0, a1, a2 = a.tolist()
    b0, b1, b2 = b.tolist()
    return np.array([a1 * b2 - a2 * b1, a2 * b0 - a0 * b2, a0 * b1 - a1 * b0])


def _signed_angle(u: NDArray[np.float64], v: NDArray[np.float64], axis: NDArray[np.float64]) -> float:
    """The angle that turns ``u`` onto ``v`` about unit ``axis`` (both taken perpendicular to it)."""
    u = u - axis * float(axis @ u)
    v = v - axis * float(axis @ v)
    return math.atan2(float(axis @ _cross(u, v)), float(u @ v))


@dataclass(frozen=True)
class ClosedFormIK:
    """The zero-configuration geometry of a UR-type chain in the base frame: joint axes (6, 3) (unit) and a point on
    each (6, 3), the wrist point (3,) where axes 5 and 6 meet, and the camera pose ``M0`` (4, 4) at q = 0."""

    axes: NDArray[np.float64]
    points: NDArray[np.float64]
    wrist: NDArray[np.float64]
    M0: NDArray[np.float64]
    check: bool = False
    """Check every solution's pose by forward kinematics (the self-check's); else only those whose subproblems
    were clamped onto the workspace's boundary or met the wrist singularity (the others are exact)."""
    _M0_inv: NDArray[np.float64] = field(init=False, repr=False)
    _e: NDArray[np.float64] = field(init=False, repr=False)
    _c1: float = field(init=False, repr=False)
    _a5: float = field(init=False, repr=False)
    _b5: float = field(init=False, repr=False)
    _k5: float = field(init=False, repr=False)
    _a3: float = field(init=False, repr=False)
    _b3: float = field(init=False, repr=False)
    _l3: float = field(init=False, repr=False)

    def __post_init__(self) -> None:
        """The pose-independent parts of the subproblems, computed once."""
        w, p = self.axes, self.points
        e = _cross(w[1], np.array([1.0, 0.0, 0.0]))
        if np.linalg.norm(e) < 0.1:
            e = _cross(w[1], np.array([0.0, 1.0, 0.0]))
        to_elbow = p[3] - p[2]
        to_shoulder = p[1] - p[2]
        to_elbow -= w[1] * float(w[1] @ to_elbow)
        to_shoulder -= w[1] * float(w[1] @ to_shoulder)
        w25, w56 = float(w[1] @ w[4]), float(w[4] @ w[5])
        constants = {
            "_M0_inv": np.linalg.inv(self.M0),
            "_e": e / np.linalg.norm(e),  # a unit vector across joint 2's axis (the planar arm's total angle)
            "_c1": float(w[1] @ (self.wrist - p[0])),
            "_a5": float(w[1] @ w[5]) - w25 * w56,
            "_b5": float(w[1] @ _cross(w[4], w[5])),
            "_k5": w25 * w56,
            "_a3": float(to_shoulder @ to_elbow),
            "_b3": float(to_shoulder @ _cross(w[1], to_elbow)),
            "_l3": float(to_elbow @ to_elbow) + float(to_shoulder @ to_shoulder),
        }
        for name, value in constants.items():
            object.__setattr__(self, name, value)

    def solve(self, T_base_camera: Pose, reference: NDArray[np.float64] | None = None) -> list[NDArray[np.float64]]:
        """Every branch (each (6,), angles in (-pi, pi]) that puts the camera at ``T_base_camera``: at most eight;
        none when the pose is out of reach. reference (6,): joint 6's angle at the wrist singularity (else 0)."""
        w, p = self.axes, self.points
        target = np.eye(4)
        target[:3, :3] = T_base_camera.rotation
        target[:3, 3] = T_base_camera.translation
        g = target @ self._M0_inv  # e^(xi1 q1) ... e^(xi6 q6)
        wrist = g[:3, :3] @ self.wrist + g[:3, 3]
        out: list[NDArray[np.float64]] = []
        # 1. joint 1: w2 . (p1 + Rot(w1, -q1)(wrist - p1)) = w2 . wrist0
        v = wrist - p[0]
        shoulders, exact1 = _cos_sin_equation(float(w[1] @ v), -float(w[1] @ _cross(w[0], v)), self._c1)
        for q1 in shoulders:
            g1 = _screw(w[0], p[0], -q1) @ g  # e^(xi2 q2) ... e^(xi6 q6)
            R = g1[:3, :3]
            # 2. joint 5: w2 . Rot(w5, q5) w6 = w2 . R w6 (R = R234 R5 R6, and R6 leaves w6 alone)
            target6 = R.T @ w[1]
            wrists, exact5 = _cos_sin_equation(self._a5, self._b5, float(target6 @ w[5]) - self._k5)
            for q5 in wrists:
                # 3. joint 6: Rot(w6, -q6) Rot(w5, -q5) w2 = R^T w2
                u = _rot(w[4], -q5) @ w[1]
                singular = bool(np.linalg.norm(u - w[5] * float(w[5] @ u)) < SINGULAR)
                if singular:  # joint 6 is free
                    q6 = 0.0 if reference is None else wrap_angle(float(reference[5]))
                else:
                    q6 = wrap_angle(-_signed_angle(u, target6, w[5]))
                # 4. joints 2-4: G = e^(xi2 q2) e^(xi3 q3) e^(xi4 q4), a planar arm about parallel axes
                G = g1 @ _screw(w[5], p[5], -q6) @ _screw(w[4], p[4], -q5)
                reach = G[:3, :3] @ p[3] + G[:3, 3]  # joint 4's axis point, moved by joints 2 and 3 only
                span = reach - p[1]
                span -= w[1] * float(w[1] @ span)
                total = _signed_angle(self._e, G[:3, :3] @ self._e, w[1])
                elbows, exact3 = _cos_sin_equation(self._a3, self._b3, 0.5 * (self._l3 - float(span @ span)))
                check = self.check or singular or not (exact1 and exact5 and exact3)
                for q3 in elbows:
                    elbow = p[2] + _rot(w[2], q3) @ (p[3] - p[2])
                    q2 = wrap_angle(_signed_angle(elbow - p[1], reach - p[1], w[1]))
                    q = np.array([q1, q2, q3, wrap_angle(total - q2 - q3), q5, q6])
                    if not check or self.pose_error(q, target) < SOLUTION_TOLERANCE:
                        out.append(q)
        return out

    def forward(self, q: NDArray[np.float64]) -> NDArray[np.float64]:
        """(4, 4) the camera pose at configuration (6,) ``q`` (the product of exponentials)."""
        T = np.eye(4)
        for j in range(6):
            T = T @ _screw(self.axes[j], self.points[j], float(q[j]))
        return T @ self.M0

    def pose_error(self, q: NDArray[np.float64], target: NDArray[np.float64]) -> float:
        """The camera's position error (m) plus its rotation's Frobenius error at (6,) ``q`` against (4, 4)
        ``target``: about 1e-14 for a solution; a pose clamped onto the workspace's boundary errs more."""
        T = self.forward(q)
        return float(np.linalg.norm(T[:3, 3] - target[:3, 3]) + np.linalg.norm(T[:3, :3] - target[:3, :3]))


@functools.lru_cache(maxsize=8)
def closed_form(arm: ArmModel) -> ClosedFormIK | None:
    """The closed-form solver of ``arm`` if it is a UR-type chain whose solutions check out, else None (cached per
    loaded arm: about 20 ms, the self-check's)."""
    import pinocchio as pin  # pyright: ignore[reportMissingImports]  (under cmeel.prefix)

    model: Any = arm.model
    if model.nq != 6 or model.njoints != 7:
        return None
    data = model.createData()
    q0 = np.zeros(6)
    pin.computeJointJacobians(model, data, q0)
    pin.framesForwardKinematics(model, data, q0)
    axes, points = [], []
    for j in range(1, 7):
        if model.parents[j] != j - 1:
            return None  # not a serial chain in order
        J = np.array(pin.getJointJacobian(model, data, j, pin.WORLD))[:, j - 1]  # [v; w] of joint j at q0
        linear, angular = J[:3], J[3:]
        if abs(float(np.linalg.norm(angular)) - 1.0) > GEOMETRY_TOLERANCE:
            return None  # prismatic or scaled: not a revolute joint
        axes.append(angular)
        points.append(_cross(angular, linear))  # v = -w x p  =>  p = w x v (the axis point nearest the origin)
    w, p = np.array(axes), np.array(points)
    tol = GEOMETRY_TOLERANCE
    if any(np.linalg.norm(_cross(w[1], w[k])) > tol for k in (2, 3)) or abs(float(w[0] @ w[1])) > tol:
        return None
    n56 = _cross(w[4], w[5])
    if np.linalg.norm(n56) < 1e-3 or abs(float((p[5] - p[4]) @ n56)) / np.linalg.norm(n56) > tol:
        return None  # axes 5 and 6 parallel or skew: no wrist point
    # the wrist point: where axis 5 meets axis 6 (least squares of p4 + s w5 = p5 + t w6)
    s, t = np.linalg.lstsq(np.column_stack([w[4], -w[5]]), p[5] - p[4], rcond=None)[0]
    wrist = 0.5 * (p[4] + s * w[4] + p[5] + t * w[5])
    M = data.oMf[arm.camera_frame]
    M0 = np.eye(4)
    M0[:3, :3], M0[:3, 3] = np.array(M.rotation), np.array(M.translation)
    checked, solver = ClosedFormIK(w, p, wrist, M0, check=True), ClosedFormIK(w, p, wrist, M0)
    rng = np.random.default_rng(0)
    for _ in range(SELF_CHECK_CONFIGURATIONS):  # the solver must find each configuration back, to whole turns
        q = rng.uniform(-math.pi, math.pi, 6)
        pin.framesForwardKinematics(model, data, q)
        M = data.oMf[arm.camera_frame]
        T = Pose.trusted(np.array(M.rotation), np.array(M.translation))
        found = checked.solve(T, q)
        if not any(np.max(np.abs(np.remainder(s - q + math.pi, 2 * math.pi) - math.pi)) < 1e-5 for s in found):
            return None
        if len(solver.solve(T, q)) != len(found):
            return None  # a branch the subproblems call exact is not
    return solver
