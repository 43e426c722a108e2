"""Point-to-plane ICP of a new frame to the accumulated cloud, with an acceptance gate.

The camera pose a robot reports is a little wrong; ICP measures by how much.

- A new frame overlaps the cloud only partly: its new surfaces find wrong
  partners near the old ones' edges. A Tukey robust kernel (scale ``max_rmse``)
  keeps them from pulling the result.
- The overlap may not pin the pose down (a sphere turns freely about its centre,
  a mug about its axis, two box faces let it slide along their edge). ICP then
  drifts along those directions, pulled by the partial overlap (a mug seen 30
  degrees further round is turned back by ~30 degrees). They are found from the
  point-to-plane information matrix at the start (eigenvalues below
  ``DEGENERACY_RATIO`` of the largest), and ICP then runs one step at a time with
  the motion along them removed after each step: what the data cannot tell, stays
  as the robot reported it.
- A result is used only when it looks trustworthy: enough of the frame found a
  partner in the cloud (fitness), the partners are close (rmse), and the
  correction is small (a large jump means ICP slid into a wrong alignment).

open3d is imported inside :func:`register` only (the planner does not import it at import time).
"""

from __future__ import annotations

import threading
from collections.abc import Iterator
from contextlib import contextmanager
from dataclasses import dataclass
from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

from planner.config import RegistrationConfig
from planner.types import Pose
from planner.validate import checked_array

SOURCE_VOXEL_FRACTION = 0.5
"""ICP uses the source down-sampled to voxels of this fraction of ``max_correspondence`` (centroid per voxel)."""

ROTATION_LEVER = 0.5
"""Metres: when a free direction mixes rotation and translation, the correction keeps the least
rotation as if every radian moved points this far (about the camera's working distance)."""

DEGENERACY_RATIO = 0.01
"""Directions of the 6-D pose whose information (point-to-plane, rotations scaled by the
RMS radius of the source) is below this fraction of the best-constrained one are left uncorrected."""


@dataclass(frozen=True, eq=False)
class RegistrationResult:
    """What ICP found and whether to use it.

    correction: maps the source's world to the corrected world
    (``T_world_camera_new = correction @ T_world_camera``); the identity when not accepted.
    fitness: fraction of (down-sampled) source points with a target point within ``max_correspondence``.
    rmse: RMS point-to-plane distance of those inlier pairs (along the target normal), metres.
    accepted: every gate passed. reason: "ok: ..." or which gates failed, with the numbers.
    shift: how far ICP's transform moves the source centroid, metres (also when rejected).
    unconstrained: how many of the 6 pose directions the overlap did not constrain (left uncorrected).
    """

    correction: Pose
    fitness: float
    rmse: float
    accepted: bool
    reason: str
    shift: float = 0.0
    unconstrained: int = 0

    def summary(self) -> dict[str, bool | float | str]:
        """``{"accepted", "fitness", "rmse", "reason"}``: what a scan's metrics and a session's journal record."""
        return {"accepted": self.accepted, "fitness": self.fitness, "rmse": self.rmse, "reason": self.reason}


def _rejected(
    reason: str, fitness: float = 0.0, rmse: float = 0.0, shift: float = 0.0, free: int = 0
) -> RegistrationResult:
    return RegistrationResult(Pose.identity(), fitness, rmse, False, reason, shift, free)


def register(source_world: ArrayLike, target_world: ArrayLike, config: RegistrationConfig) -> RegistrationResult:
    """Align ``source_world`` (N, 3) to ``target_world`` (M, 3) by point-to-plane ICP, starting at the identity.

    The source is down-sampled to voxels of ``SOURCE_VOXEL_FRACTION * max_correspondence``
    (fitness and rmse refer to those points). Target normals are estimated from
    neighbours within 3 * ``max_correspondence`` (at most 30); residuals are weighted
    by a Tukey kernel of scale ``max_rmse``; motion along directions the overlap does
    not constrain is removed (see the module docstring). Accepted only if
    fitness >= ``min_fitness``, rmse <= ``max_rmse`` and the shift of the source
    centroid <= ``max_correction``; otherwise the correction is the identity and
    ``reason`` lists every failed gate.
    Fewer than 3 source or target points, or ``enabled = False``, give a rejected
    result saying so. Non-finite input is a ValueError.
    """
    src = checked_array("source_world", source_world, (None, 3))
    tgt = checked_array("target_world", target_world, (None, 3))
    if not config.enabled:
        return _rejected("registration disabled")
    if len(src) < 3:
        return _rejected(f"source has {len(src)} points (need >= 3)")
    if len(tgt) < 3:
        return _rejected(f"target has {len(tgt)} points (need >= 3)")

    import open3d as o3d

    with _one_open3d_thread(o3d):
        return _register(src, tgt, config, o3d)


_OPEN3D_THREADS = threading.Lock()


@contextmanager
def _one_open3d_thread(o3d: Any) -> Iterator[None]:
    """Run open3d on one thread, one registration at a time: its parallel reductions sum in an order that
    depends on the thread count and the load, so the same frames would give corrections that differ in the
    last bits, and a resumed or concurrent session would drift from its twin. One thread costs nothing
    measurable here (20 ms either way on a bunny frame)."""
    with _OPEN3D_THREADS:
        before = o3d.utility.get_max_threads()
        o3d.utility.set_max_threads(1)
        try:
            yield
        finally:
            o3d.utility.set_max_threads(before)


def _register(
    src: NDArray[np.float64], tgt: NDArray[np.float64], config: RegistrationConfig, o3d: Any
) -> RegistrationResult:
    """``register`` past the input checks; open3d already on one thread."""
    reg = o3d.pipelines.registration
    source = o3d.geometry.PointCloud(o3d.utility.Vector3dVector(np.array(src, dtype=np.float64)))
    source = source.voxel_down_sample(SOURCE_VOXEL_FRACTION * config.max_correspondence)
    src_icp = np.asarray(source.points)
    target = o3d.geometry.PointCloud(o3d.utility.Vector3dVector(np.array(tgt, dtype=np.float64)))
    target.estimate_normals(o3d.geometry.KDTreeSearchParamHybrid(radius=3.0 * config.max_correspondence, max_nn=30))
    estimation = reg.TransformationEstimationPointToPlane(reg.TukeyLoss(k=config.max_rmse))
    initial = reg.evaluate_registration(source, target, config.max_correspondence, np.eye(4))
    pairs = np.asarray(initial.correspondence_set, dtype=np.int64).reshape(-1, 2)
    free_basis = _free_directions(src_icp, np.asarray(target.normals), pairs)
    free = free_basis.shape[1]
    if free == 0:
        criteria = reg.ICPConvergenceCriteria(max_iteration=config.max_iterations)
        result = reg.registration_icp(source, target, config.max_correspondence, np.eye(4), estimation, criteria)
        T = np.asarray(result.transformation, dtype=np.float64)
    else:  # one step at a time, removing the motion along the free directions after each
        T = np.eye(4)
        step = reg.ICPConvergenceCriteria(max_iteration=1)
        for _ in range(config.max_iterations):
            moved = reg.registration_icp(source, target, config.max_correspondence, T, estimation, step).transformation
            T_next = _remove_free_motion(np.asarray(moved, dtype=np.float64), free_basis, src_icp)
            done = np.abs(T_next - T).max() < 1e-5
            T = T_next
            if done:
                break
        result = reg.evaluate_registration(source, target, config.max_correspondence, T)
    correction = Pose(_orthonormalize(T[:3, :3]), T[:3, 3])
    centroid = src.mean(axis=0)
    shift = float(np.linalg.norm(correction.apply(centroid[None])[0] - centroid))
    pairs = np.asarray(result.correspondence_set, dtype=np.int64).reshape(-1, 2)
    fitness = float(result.fitness)
    rmse = _plane_rmse(
        correction.apply(src_icp[pairs[:, 0]]), tgt[pairs[:, 1]], np.asarray(target.normals)[pairs[:, 1]]
    )

    failed = []
    if fitness < config.min_fitness:
        failed.append(f"fitness {fitness:.3f} < min_fitness {config.min_fitness:.3f}")
    if rmse > config.max_rmse:
        failed.append(f"rmse {rmse * 1000:.2f} mm > max_rmse {config.max_rmse * 1000:.2f} mm")
    if shift > config.max_correction:
        failed.append(f"correction {shift * 1000:.1f} mm > max_correction {config.max_correction * 1000:.1f} mm")
    if failed:
        return _rejected("rejected: " + "; ".join(failed), fitness, rmse, shift, free)
    reason = f"ok: fitness {fitness:.3f}, rmse {rmse * 1000:.2f} mm, correction {shift * 1000:.1f} mm"
    if free:
        reason += f"; {free} unconstrained direction(s) left uncorrected"
    return RegistrationResult(correction, fitness, rmse, True, reason, shift, free)


def _plane_rmse(p: NDArray[np.float64], q: NDArray[np.float64], n: NDArray[np.float64]) -> float:
    """RMS point-to-plane distance |n . (p - q)| of pairs (K, 3); 0.0 for no pairs.

    Unlike the point-to-point distance it does not grow with the spacing of the
    target's points (2.5 mm after down-sampling), only with noise and misalignment.
    """
    if len(p) == 0:
        return 0.0
    return float(np.sqrt(np.mean(np.einsum("ij,ij->i", p - q, n) ** 2)))


def _rms_radius(src: NDArray[np.float64]) -> float:
    """RMS distance of the points (N, 3) from their centroid, metres (the length that scales rotations)."""
    return float(np.sqrt(np.mean(np.sum((src - src.mean(axis=0)) ** 2, axis=1))))


def _free_directions(
    src: NDArray[np.float64], normals: NDArray[np.float64], pairs: NDArray[np.int64]
) -> NDArray[np.float64]:
    """(6, k) orthonormal basis of the pose directions the correspondences do not constrain (k may be 0).

    src: (N, 3) source points; normals: (M, 3) target normals; pairs: (K, 2) (source, target)
    correspondences. A motion is written about the source centroid c as xi = (omega * L, d):
    rotation vector omega scaled by the RMS radius L, and the centroid displacement d. Its
    point-to-plane information matrix is H = mean(J^T J), J = [((p - c) x n) / L, n]; eigenvectors
    with eigenvalues below DEGENERACY_RATIO * max are free.
    """
    L = _rms_radius(src)
    if len(pairs) < 6 or not L > 0:
        return np.zeros((6, 0))
    p = src[pairs[:, 0]] - src.mean(axis=0)
    n = normals[pairs[:, 1]]
    J = np.hstack([np.cross(p, n) / L, n])
    eigenvalues, vectors = np.linalg.eigh(J.T @ J / len(J))
    return vectors[:, eigenvalues < DEGENERACY_RATIO * eigenvalues[-1]]


def _remove_free_motion(
    T: NDArray[np.float64], free: NDArray[np.float64], src: NDArray[np.float64]
) -> NDArray[np.float64]:
    """``T`` (4, 4) minus its motion along the ``free`` directions (6, k) (motion as in _free_directions).

    The data fit ``T`` and ``T`` moved along free directions equally well; of those, this keeps
    the one with the least rotation (rotations weighted by ROTATION_LEVER, translations by 1),
    so a sphere's or a mug's free spin is dropped rather than traded for a translation.
    """
    c, L = src.mean(axis=0), _rms_radius(src)
    R = T[:3, :3]
    xi = np.concatenate([_rotvec(R) * L, R @ c + T[:3, 3] - c])
    weight = np.array([ROTATION_LEVER / L] * 3 + [1.0] * 3)
    alpha, *_ = np.linalg.lstsq(weight[:, None] * free, weight * xi, rcond=None)
    xi = xi - free @ alpha
    R_new = _rotation(xi[:3] / L)
    out = np.eye(4)
    out[:3, :3] = R_new
    out[:3, 3] = c + xi[3:] - R_new @ c
    return out


def _rotvec(R: NDArray[np.float64]) -> NDArray[np.float64]:
    """(3,) rotation vector of a rotation matrix (for angles well below pi, as ICP corrections are)."""
    angle = float(np.arccos(np.clip((np.trace(R) - 1.0) / 2.0, -1.0, 1.0)))
    axis = np.array([R[2, 1] - R[1, 2], R[0, 2] - R[2, 0], R[1, 0] - R[0, 1]])
    s = 2.0 * np.sin(angle)
    return axis / 2.0 if abs(s) < 1e-12 else axis * (angle / s)


def _rotation(rotvec: NDArray[np.float64]) -> NDArray[np.float64]:
    """(3, 3) rotation matrix of a rotation vector (Rodrigues)."""
    angle = float(np.linalg.norm(rotvec))
    K = np.array([[0.0, -rotvec[2], rotvec[1]], [rotvec[2], 0.0, -rotvec[0]], [-rotvec[1], rotvec[0], 0.0]])
    if angle < 1e-12:
        return np.eye(3) + K
    K /= angle
    return np.eye(3) + np.sin(angle) * K + (1.0 - np.cos(angle)) * (K @ K)


def _orthonormalize(R: NDArray[np.float64]) -> NDArray[np.float64]:
    """The rotation nearest to ``R`` (3, 3) (removes round-off from ICP's composed updates)."""
    U, _, Vt = np.linalg.svd(R)
    D = np.diag([1.0, 1.0, np.sign(np.linalg.det(U @ Vt))])
    return U @ D @ Vt
