"""The estimate: hand-eye transform and turntable axis from the sphere centres of all captures.

Model of capture i, sphere j (centre ``p_j`` fixed to the plate)::

    c_ij (camera) = (T_base_flange_i @ X)^-1 @ A @ Rz(theta_i + dtheta_i) @ A^-1 @ p_j

X = ``T_flange_camera``; A = the axis frame in the base frame (its z the axis, its origin where the axis crosses
z = 0: two tilt angles, two offsets); ``dtheta_i`` the plate's angle error at capture i (a prior of
``angle_sigma_deg`` keeps them small and fixes the one freedom they share with the ``p_j``). Start: OpenCV's
``calibrateHandEye`` (Park) on the flange poses in the nominal plate frame and the target's pose in each frame
(``Rotation.align_vectors`` of the fitted centres onto the built ones); then scipy ``least_squares`` over every
centre residual refines X, A, the p_j and the dtheta_i. Uncertainty: the covariance ``s^2 (J^T J)^-1`` at the
solution (``s^2`` the residual variance).
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray
from scipy.optimize import least_squares
from scipy.spatial.transform import Rotation

from devices.calibration.result import CalibrationError, CalibrationResult, Capture
from devices.calibration.target import SphereTarget
from planner.types import Pose

MIN_CAPTURES = 6
"""Captures that saw at least three spheres needed for an estimate."""
MIN_PLATE_ANGLES = 3
"""Distinct plate angles (0.5 degree apart or more) needed for the axis."""
MIN_SECOND_AXIS = 0.02
"""The flange's rotations between captures must not all be about one axis: the second eigenvalue of the summed
outer products of their unit axes, relative to the first, must be at least this."""
CENTRE_SIGMA = 0.0003
"""Expected error of one fitted centre, metres (weighs the plate-angle prior against the centre residuals)."""


def _rz(theta: NDArray[np.float64]) -> NDArray[np.float64]:
    """(C, 3, 3) rotations about z."""
    c, s = np.cos(theta), np.sin(theta)
    R = np.zeros((len(theta), 3, 3))
    R[:, 0, 0], R[:, 0, 1], R[:, 1, 0], R[:, 1, 1], R[:, 2, 2] = c, -s, s, c, 1.0
    return R


def check_captures(captures: Sequence[Capture]) -> list[Capture]:
    """The captures that saw at least three spheres; CalibrationError when they cannot give an estimate (too few,
    too few plate angles, flange rotations all about one axis)."""
    if not captures:
        raise CalibrationError("calibration: no captures")
    if not any(c.seen.any() for c in captures):
        raise CalibrationError(f"calibration: the target was not seen in any of the {len(captures)} captures")
    usable = [c for c in captures if int(c.seen.sum()) >= 3]
    if len(usable) < MIN_CAPTURES:
        raise CalibrationError(
            f"calibration: {len(usable)} captures saw three or more spheres, need at least {MIN_CAPTURES}"
        )
    angles = np.sort(np.unique(np.round(np.degrees([c.plate_angle for c in usable]) * 2) / 2))
    if len(angles) < MIN_PLATE_ANGLES:
        raise CalibrationError(
            f"calibration: captures at {len(angles)} plate angles, need at least {MIN_PLATE_ANGLES} for the axis"
        )
    R = [Rotation.from_matrix(_rz(np.array([-c.plate_angle]))[0] @ c.T_base_flange.rotation) for c in usable]
    scatter = np.zeros((3, 3))
    for i in range(len(R)):
        for k in range(i + 1, len(R)):
            rotvec = (R[i].inv() * R[k]).as_rotvec()
            angle = float(np.linalg.norm(rotvec))
            if angle > math.radians(3):
                a = rotvec / angle
                scatter += np.outer(a, a)
    eig = np.sort(np.linalg.eigvalsh(scatter))[::-1]
    if eig[0] <= 0 or eig[1] / eig[0] < MIN_SECOND_AXIS:
        raise CalibrationError(
            "calibration: degenerate poses: the camera turns about one axis only between captures "
            "(the hand-eye transform is not observable); vary the tilt and roll of the views"
        )
    return usable


def target_pose(centres_camera: NDArray[np.float64], centres_target: NDArray[np.float64]) -> Pose:
    """``T_camera_target`` from (K, 3) fitted centres (NaN rows skipped) and the built ones (K, 3)."""
    seen = np.all(np.isfinite(centres_camera), axis=1)
    a, b = centres_camera[seen], centres_target[seen]
    R = Rotation.align_vectors(a - a.mean(axis=0), b - b.mean(axis=0))[0].as_matrix()
    return Pose(R, a.mean(axis=0) - R @ b.mean(axis=0))


def initial_hand_eye(captures: Sequence[Capture], target: SphereTarget) -> Pose:
    """OpenCV's ``calibrateHandEye`` (Park's method) with the flange in the nominal plate frame."""
    import cv2

    R_g, t_g, R_t, t_t = [], [], [], []
    for c in captures:
        T_table_flange = Pose(_rz(np.array([-c.plate_angle]))[0], np.zeros(3)) @ c.T_base_flange
        T_camera_target = target_pose(c.centres_camera, target.centres_table)
        R_g.append(T_table_flange.rotation)
        t_g.append(T_table_flange.translation.reshape(3, 1))
        R_t.append(T_camera_target.rotation)
        t_t.append(T_camera_target.translation.reshape(3, 1))
    R, t = cv2.calibrateHandEye(R_g, t_g, R_t, t_t, method=cv2.CALIB_HAND_EYE_PARK)
    R = np.asarray(R, dtype=np.float64)
    u, _, vt = np.linalg.svd(R)
    return Pose(u @ vt, np.asarray(t, dtype=np.float64).reshape(3))


@dataclass(frozen=True)
class ErrorBudget:
    """The errors a calibration's residuals cannot show in full, one sigma per axis, added to the covariance.

    arm_translation, arm_rotation_deg: the arm's repeatability, a small displacement of the camera per move shared
    by all the sphere centres of its capture (metres, degrees; the 'poor' simulation's figures, a UR5 CB3 spec is
    +-0.1 mm). centre_bias: a bias of every fitted centre along each camera axis, the same in every capture (a
    depth sensor's range bias, flying pixels at the sphere's rim): it moves the hand-eye translation one to one and
    no residual shows it (metres).
    """

    arm_translation: float = 0.0003
    arm_rotation_deg: float = 0.01
    centre_bias: float = 0.0002


def covariance(
    J: NDArray[np.float64],
    r: NDArray[np.float64],
    capture_of: NDArray[np.int_],
    pred_camera: NDArray[np.float64],
    budget: ErrorBudget,
) -> NDArray[np.float64]:
    """The parameters' covariance at the least-squares solution: the residuals' own ``s^2 (J^T J)^-1`` (``s^2``
    the residual variance, the reduced chi-square) plus ``budget`` propagated through the solution's sensitivity
    ``H^-1 J^T``. J: (M, P) the residuals' Jacobian (the first 3 S rows: the S sightings' centres); r: (M,)
    the residuals; capture_of: (S,) each sighting's capture; pred_camera: (S, 3) the predicted centres (camera
    frame). A camera displacement (dt, dr) moves a sighting by ``-dt + pred x dr``; a centre bias b by ``b``."""
    H_inv = np.linalg.pinv(J.T @ J)
    s2 = float(r @ r) / max(len(r) - J.shape[1], 1)
    S = len(capture_of)
    G = H_inv @ J[: 3 * S].T  # (P, 3S): the solution's change per unit change of each centre coordinate
    cov = H_inv * s2
    move = np.diag([budget.arm_translation**2] * 3 + [math.radians(budget.arm_rotation_deg) ** 2] * 3)
    for c in np.unique(capture_of):
        rows = np.nonzero(capture_of == c)[0]
        B = np.zeros((3 * len(rows), 6))
        for n, (x, y, z) in enumerate(pred_camera[rows]):
            B[3 * n : 3 * n + 3, :3] = -np.eye(3)
            B[3 * n : 3 * n + 3, 3:] = np.array([[0.0, -z, y], [z, 0.0, -x], [-y, x, 0.0]])
        Gc = G[:, (3 * rows[:, None] + np.arange(3)).ravel()] @ B  # (P, 6)
        cov += Gc @ move @ Gc.T
    Gb = G.reshape(G.shape[0], S, 3).sum(axis=1)  # (P, 3): a bias common to every sighting
    return cov + Gb @ Gb.T * budget.centre_bias**2


def norm_bound(cov: NDArray[np.float64], level: float = 0.95, draws: int = 20000) -> float:
    """The ``level`` quantile of ``|e|`` for ``e ~ N(0, cov)`` (cov: (n, n)), by seeded Monte Carlo: the bound the
    error's norm stays within at that level (for an isotropic 3D error, 1.62 times the root of the trace)."""
    L = np.linalg.cholesky(cov + np.eye(len(cov)) * 1e-30)
    e = np.random.default_rng(0).standard_normal((draws, len(cov))) @ L.T
    return float(np.quantile(np.linalg.norm(e, axis=1), level))


def estimate(
    captures: Sequence[Capture],
    target: SphereTarget,
    angle_sigma_deg: float = 0.1,
    budget: ErrorBudget = ErrorBudget(),
) -> CalibrationResult:
    """The hand-eye transform and the turntable axis from ``captures`` of ``target`` (see the module docstring).
    angle_sigma_deg: the plate angle's expected error per move (0: angles taken as exact). budget: the errors added
    to the residuals' covariance (:class:`ErrorBudget`). CalibrationError when the captures cannot give an estimate
    or the solver fails."""
    usable = check_captures(captures)
    X0 = initial_hand_eye(usable, target)
    C, K = len(usable), target.count
    T_bf = np.stack([c.T_base_flange.matrix for c in usable])  # (C, 4, 4)
    theta = np.array([c.plate_angle for c in usable])
    obs = np.stack([c.centres_camera for c in usable])  # (C, K, 3)
    seen = np.all(np.isfinite(obs), axis=2)
    ci, kj = np.nonzero(seen)
    obs_seen = obs[ci, kj]
    # start for the centres: every sighting mapped into the nominal plate frame, averaged
    T_bc0 = T_bf @ X0.matrix
    p_base = np.einsum("cab,cb->ca", T_bc0[ci, :3, :3], obs_seen) + T_bc0[ci, :3, 3]
    p_table = np.einsum("cba,cb->ca", _rz(theta[ci]), p_base)
    P0 = np.stack([p_table[kj == k].mean(axis=0) for k in range(K)])
    free_angles = angle_sigma_deg > 0
    prior = CENTRE_SIGMA / math.radians(angle_sigma_deg) if free_angles else 0.0
    n_angle = C if free_angles else 0

    def unpack(x: NDArray[np.float64]) -> tuple[Pose, Pose, NDArray[np.float64], NDArray[np.float64]]:
        X = Pose(X0.rotation @ Rotation.from_rotvec(x[0:3]).as_matrix(), X0.translation + X0.rotation @ x[3:6])
        A = Pose(Rotation.from_rotvec([x[6], x[7], 0.0]).as_matrix(), np.array([x[8], x[9], 0.0]))
        P = x[10 : 10 + 3 * K].reshape(K, 3)
        dtheta = x[10 + 3 * K :] if free_angles else np.zeros(C)
        return X, A, P, dtheta

    def residual(x: NDArray[np.float64]) -> NDArray[np.float64]:
        X, A, P, dtheta = unpack(x)
        T_bc = T_bf @ X.matrix  # (C, 4, 4) base <- camera
        R_cb = np.transpose(T_bc[:, :3, :3], (0, 2, 1))
        t_cb = -np.einsum("cab,cb->ca", R_cb, T_bc[:, :3, 3])
        p_axis = (P - A.translation) @ A.rotation  # A^-1 p  (K, 3)
        Rz = _rz(theta + dtheta)
        p_b = np.einsum("ab,cbd,kd->cka", A.rotation, Rz, p_axis) + A.translation  # (C, K, 3)
        pred = np.einsum("cab,ckb->cka", R_cb, p_b) + t_cb[:, None, :]
        r = (obs_seen - pred[ci, kj]).ravel()
        return np.concatenate([r, prior * dtheta]) if free_angles else r

    x0 = np.concatenate([np.zeros(10), P0.ravel(), np.zeros(n_angle)])
    solution = least_squares(residual, x0, method="trf", x_scale="jac", ftol=1e-12, xtol=1e-12, gtol=1e-12)
    if not solution.success:
        raise CalibrationError(f"calibration: the least-squares fit did not converge ({solution.message})")
    X, A, P, _ = unpack(solution.x)
    data = solution.fun[: 3 * len(ci)]
    cov = covariance(solution.jac, solution.fun, ci, obs_seen - data.reshape(-1, 3), budget)
    per_capture = np.array([math.sqrt(float(np.mean(data.reshape(-1, 3)[ci == i] ** 2)) * 3) * 1000 for i in range(C)])
    return CalibrationResult(
        T_flange_camera=X,
        axis_point_base=A.translation.copy(),
        axis_direction_base=A.rotation[:, 2].copy(),
        centres_table=P.copy(),
        hand_eye_std_mm=math.sqrt(float(np.trace(cov[3:6, 3:6]))) * 1000,
        hand_eye_std_deg=math.degrees(math.sqrt(float(np.trace(cov[0:3, 0:3])))),
        axis_std_mm=math.sqrt(float(np.trace(cov[8:10, 8:10]))) * 1000,
        axis_std_deg=math.degrees(math.sqrt(float(np.trace(cov[6:8, 6:8])))),
        residuals_mm=per_capture,
        rms_mm=math.sqrt(float(np.mean(data**2)) * 3) * 1000,
        labels=tuple(c.label for c in usable),
        hand_eye_bound95_mm=norm_bound(cov[3:6, 3:6]) * 1000,
        hand_eye_bound95_deg=math.degrees(norm_bound(cov[0:3, 0:3])),
        axis_bound95_mm=norm_bound(cov[8:10, 8:10]) * 1000,
        axis_bound95_deg=math.degrees(norm_bound(cov[6:8, 6:8])),
        T_flange_camera_initial=X0,
    )
