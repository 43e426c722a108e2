"""Frozen value types that cross module boundaries.

Conventions (see ARCHITECTURE.md):

- The planner's ``world`` frame is the turntable frame: z-up, origin at the
  centre of the plate's top surface, rotating with the plate. Devices convert
  from the robot base frame.
- ``T_a_b`` maps coordinates in frame ``b`` to frame ``a``.
- Cameras use OpenCV axes: +z forward, +x right, +y down.
- Lengths in metres, angles in radians.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from enum import IntEnum
from functools import cached_property
from typing import Literal

import numpy as np
from numpy.typing import ArrayLike, NDArray

from planner.validate import check_positive, checked_array

EllipsoidKind = Literal["occupied", "frontier"]


class VoxelClass(IntEnum):
    """The five voxel classes of paper §III-C (values are the stored uint8 codes)."""

    NONE = 0
    EMPTY = 1
    OCCUPIED = 2
    UNKNOWN = 3
    FRONTIER = 4


# --------------------------------------------------------------------------- Pose


QUATERNION_ZERO = 1e-9
"""A quaternion whose largest component is below this has no direction (refused as zero)."""


def unit_quaternion(q: NDArray[np.float64]) -> NDArray[np.float64]:
    """(4,) ``q`` (finite) scaled to unit length, in the same direction. Scaled by its largest absolute component
    first, so no square overflows or underflows: ``[1e200] * 4`` is (0.5, 0.5, 0.5, 0.5) and ``[1e308, 1e308, 0, 0]``
    is (0.7071, 0.7071, 0, 0), never identity. ValueError for a zero (or non-finite) quaternion."""
    if not np.all(np.isfinite(q)):
        raise ValueError("wxyz: must be finite numbers")
    largest = float(np.max(np.abs(q)))
    if largest < QUATERNION_ZERO:
        raise ValueError("wxyz: zero quaternion")
    scaled = q / largest  # components in [-1, 1], one of them +-1: its norm is in [1, 2]
    return scaled / np.linalg.norm(scaled)


@dataclass(frozen=True, eq=False)
class Pose:
    """A rigid transform ``T_a_b``: ``x_a = rotation @ x_b + translation``.

    rotation: (3, 3) float64, orthonormal with det +1.
    translation: (3,) float64.
    """

    rotation: NDArray[np.float64]
    translation: NDArray[np.float64]

    def __post_init__(self) -> None:
        R = checked_array("rotation", self.rotation, (3, 3))
        t = checked_array("translation", self.translation, (3,))
        if not np.allclose(R.T @ R, np.eye(3), atol=1e-6) or np.linalg.det(R) < 0:
            raise ValueError("rotation: not a proper rotation matrix (R^T R != I or det < 0)")
        object.__setattr__(self, "rotation", R)
        object.__setattr__(self, "translation", t)

    @staticmethod
    def trusted(rotation: NDArray[np.float64], translation: NDArray[np.float64]) -> Pose:
        """A Pose from arrays the caller has already validated (hot paths only: no checks, no copy)."""
        pose = object.__new__(Pose)
        object.__setattr__(pose, "rotation", rotation)
        object.__setattr__(pose, "translation", translation)
        return pose

    @staticmethod
    def identity() -> Pose:
        return Pose(np.eye(3), np.zeros(3))

    @staticmethod
    def from_matrix(T: ArrayLike) -> Pose:
        """From a (4, 4) homogeneous matrix."""
        M = checked_array("T", T, (4, 4))
        return Pose(M[:3, :3], M[:3, 3])

    @staticmethod
    def from_wxyz(wxyz: ArrayLike, position: ArrayLike) -> Pose:
        """From a quaternion (w, x, y, z), normalised here (:func:`unit_quaternion`), and a position (3,)."""
        w, x, y, z = unit_quaternion(checked_array("wxyz", wxyz, (4,)))
        R = np.array(
            [
                [1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)],
                [2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)],
                [2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)],
            ]
        )
        return Pose(R, checked_array("position", position, (3,)))

    @staticmethod
    def look_at(eye: ArrayLike, target: ArrayLike, up: ArrayLike = (0.0, 0.0, 1.0)) -> Pose:
        """``T_world_camera`` of an OpenCV camera at ``eye`` looking at ``target``.

        Image +y points along world ``-up`` as far as possible; when the view
        direction is parallel to ``up`` the image +y is world +x.
        """
        return Pose.look_at_many(checked_array("eye", eye, (3,))[None], target, up)[0]

    @staticmethod
    def look_at_many(eyes: ArrayLike, target: ArrayLike, up: ArrayLike = (0.0, 0.0, 1.0)) -> list[Pose]:
        """``look_at`` for many eyes (C, 3) and one target (3,), vectorised (the one implementation)."""
        eyes_w = checked_array("eyes", eyes, (None, 3))
        target_w = checked_array("target", target, (3,))
        up_w = checked_array("up", up, (3,))
        z = target_w - eyes_w
        dist = np.linalg.norm(z, axis=1)
        if np.any(dist < 1e-12):
            raise ValueError("look_at: eye and target coincide")
        z /= dist[:, None]
        x = np.cross(z, up_w)
        norm = np.linalg.norm(x, axis=1)
        degenerate = norm < 1e-9
        if np.any(degenerate):
            x[degenerate] = np.cross(z[degenerate], np.array([-1.0, 0.0, 0.0]))
            norm[degenerate] = np.linalg.norm(x[degenerate], axis=1)
        x /= norm[:, None]
        y = np.cross(z, x)
        R = np.stack([x, y, z], axis=2)
        R.setflags(write=False)
        return [Pose.trusted(R[i], eyes_w[i]) for i in range(len(eyes_w))]

    @property
    def matrix(self) -> NDArray[np.float64]:
        """(4, 4) homogeneous matrix."""
        M = np.eye(4)
        M[:3, :3] = self.rotation
        M[:3, 3] = self.translation
        return M

    @property
    def wxyz(self) -> NDArray[np.float64]:
        """(4,) unit quaternion (w, x, y, z) with w >= 0."""
        R = self.rotation
        tr = np.trace(R)
        if tr > 0:
            s = 2.0 * np.sqrt(tr + 1.0)
            q = np.array([0.25 * s, (R[2, 1] - R[1, 2]) / s, (R[0, 2] - R[2, 0]) / s, (R[1, 0] - R[0, 1]) / s])
        else:
            i = int(np.argmax(np.diag(R)))
            j, k = (i + 1) % 3, (i + 2) % 3
            s = 2.0 * np.sqrt(1.0 + R[i, i] - R[j, j] - R[k, k])
            q = np.empty(4)
            q[0] = (R[k, j] - R[j, k]) / s
            q[1 + i] = 0.25 * s
            q[1 + j] = (R[j, i] + R[i, j]) / s
            q[1 + k] = (R[k, i] + R[i, k]) / s
        q /= np.linalg.norm(q)
        return q if q[0] >= 0 else -q

    def inverse(self) -> Pose:
        return Pose(self.rotation.T, -self.rotation.T @ self.translation)

    def __matmul__(self, other: Pose) -> Pose:
        return Pose(self.rotation @ other.rotation, self.rotation @ other.translation + self.translation)

    def apply(self, points: ArrayLike) -> NDArray[np.float64]:
        """Map points (N, 3) from frame b to frame a."""
        p = np.asarray(points, dtype=np.float64)
        return p @ self.rotation.T + self.translation

    def to_dict(self) -> dict[str, list[float]]:
        return {"position": self.translation.tolist(), "wxyz": self.wxyz.tolist()}

    @staticmethod
    def from_dict(d: dict) -> Pose:
        try:
            return Pose.from_wxyz(d["wxyz"], d["position"])
        except KeyError as exc:
            raise ValueError(f"pose: missing field {exc}") from None

    def __repr__(self) -> str:
        return f"Pose(position={np.round(self.translation, 4).tolist()}, wxyz={np.round(self.wxyz, 4).tolist()})"


# --------------------------------------------------------------------------- camera


@dataclass(frozen=True)
class Intrinsics:
    """Pinhole intrinsics of a ``width`` x ``height`` image (pixels)."""

    width: int = 640
    """Image columns, pixels."""
    height: int = 480
    """Image rows, pixels."""
    fx: float = 610.0
    """Focal length along x, pixels (640 px wide at 610 px: about a 55 degree horizontal field of view)."""
    fy: float = 610.0
    """Focal length along y, pixels."""
    cx: float = 319.5
    """Principal point, x, pixels (pixel centres at integer coordinates: 319.5 is the middle of 640)."""
    cy: float = 239.5
    """Principal point, y, pixels."""

    def __post_init__(self) -> None:
        if int(self.width) != self.width or self.width < 1:
            raise ValueError(f"width: must be a positive integer, got {self.width!r}")
        if int(self.height) != self.height or self.height < 1:
            raise ValueError(f"height: must be a positive integer, got {self.height!r}")
        check_positive("fx", self.fx)
        check_positive("fy", self.fy)
        for name in ("cx", "cy"):
            if not np.isfinite(getattr(self, name)):
                raise ValueError(f"{name}: must be finite")

    @property
    def K(self) -> NDArray[np.float64]:
        """(3, 3) camera matrix."""
        return np.array([[self.fx, 0.0, self.cx], [0.0, self.fy, self.cy], [0.0, 0.0, 1.0]])


@dataclass(frozen=True, eq=False)
class DepthFrame:
    """One depth image with its pose.

    depth: (H, W) float32 planar z-depth in metres; 0 means no return.
    T_world_camera: camera pose in the planner's world (turntable) frame.
    intrinsics: pinhole model; ``depth.shape == (height, width)``.
    """

    depth: NDArray[np.float32]
    T_world_camera: Pose
    intrinsics: Intrinsics = field(default_factory=Intrinsics)

    def __post_init__(self) -> None:
        d = checked_array("depth", self.depth, (self.intrinsics.height, self.intrinsics.width), np.float32)
        if np.any(d < 0):
            raise ValueError("depth: negative values")
        if not isinstance(self.T_world_camera, Pose):
            raise ValueError("T_world_camera: must be a Pose")
        object.__setattr__(self, "depth", d)

    @property
    def valid(self) -> NDArray[np.bool_]:
        """(H, W) bool mask of pixels with a return."""
        return self.depth > 0

    @cached_property
    def pixels(self) -> tuple[NDArray[np.intp], NDArray[np.intp]]:
        """(rows (N,), columns (N,)) of the valid pixels, row-major: the order of ``points_camera``."""
        v, u = np.nonzero(self.depth > 0)
        return v, u

    @cached_property
    def points_camera(self) -> NDArray[np.float64]:
        """(N, 3) float64 back-projected valid pixels, camera frame, row-major pixel order."""
        v, u = self.pixels
        z = self.depth[v, u].astype(np.float64)
        k = self.intrinsics
        return np.column_stack([(u - k.cx) * z / k.fx, (v - k.cy) * z / k.fy, z])

    @cached_property
    def points_world(self) -> NDArray[np.float64]:
        """(N, 3) float64 back-projected valid pixels in the world frame."""
        return self.T_world_camera.apply(self.points_camera)

    def with_pose(self, T_world_camera: Pose) -> DepthFrame:
        """The same image with a corrected pose (e.g. after ICP)."""
        return DepthFrame(self.depth, T_world_camera, self.intrinsics)

    @staticmethod
    def from_points(points_world: ArrayLike, T_world_camera: Pose, intrinsics: Intrinsics) -> DepthFrame:
        """Z-buffer world points (N, 3) into a depth image (nearest point per pixel).

        This is how recorded point clouds (PLY + pose) enter the planner.
        """
        p_w = checked_array("points_world", points_world, (None, 3))
        p_c = T_world_camera.inverse().apply(p_w)
        z = p_c[:, 2]
        front = z > 1e-6
        p_c, z = p_c[front], z[front]
        k = intrinsics
        u = np.round(k.fx * p_c[:, 0] / z + k.cx).astype(np.int64)
        v = np.round(k.fy * p_c[:, 1] / z + k.cy).astype(np.int64)
        inside = (u >= 0) & (u < k.width) & (v >= 0) & (v < k.height)
        u, v, z = u[inside], v[inside], z[inside]
        depth = np.full((k.height, k.width), np.inf)
        np.minimum.at(depth, (v, u), z)
        depth[~np.isfinite(depth)] = 0.0
        return DepthFrame(depth.astype(np.float32), T_world_camera, intrinsics)


# --------------------------------------------------------------------------- geometry


@dataclass(frozen=True, eq=False)
class BoundingBox:
    """Axis-aligned box in the world frame. lower, upper: (3,) float64, lower <= upper."""

    lower: NDArray[np.float64]
    upper: NDArray[np.float64]

    def __post_init__(self) -> None:
        lo = checked_array("lower", self.lower, (3,))
        hi = checked_array("upper", self.upper, (3,))
        if np.any(hi < lo):
            raise ValueError(f"upper: must be >= lower componentwise, got {hi} < {lo}")
        object.__setattr__(self, "lower", lo)
        object.__setattr__(self, "upper", hi)

    @property
    def center(self) -> NDArray[np.float64]:
        return 0.5 * (self.lower + self.upper)

    @property
    def extent(self) -> NDArray[np.float64]:
        return self.upper - self.lower

    @property
    def diagonal(self) -> float:
        return float(np.linalg.norm(self.extent))

    def contains(self, points: ArrayLike, margin: float = 0.0) -> NDArray[np.bool_]:
        """(N,) bool: points (N, 3) inside the box grown by ``margin``."""
        p = np.asarray(points, dtype=np.float64)
        return np.all((p >= self.lower - margin) & (p <= self.upper + margin), axis=1)


@dataclass(frozen=True, eq=False)
class Ellipsoid:
    """{x : (x - center)^T R diag(axes)^-2 R^T (x - center) <= 1}.

    center: (3,) float64; axes: (3,) float64 semi-axis lengths > 0;
    rotation: (3, 3) float64, columns are the principal directions.
    kind: which voxel class the cluster came from.
    n_points: voxels in the cluster.
    gmm_mean, gmm_covariance: the Gaussian component the cluster came from
    ((3,), (3, 3)), kept for debugging fits by eye; gmm_weight: that component's mixture weight.
    """

    center: NDArray[np.float64]
    axes: NDArray[np.float64]
    rotation: NDArray[np.float64]
    kind: EllipsoidKind
    n_points: int = 0
    gmm_mean: NDArray[np.float64] | None = None
    gmm_covariance: NDArray[np.float64] | None = None
    gmm_weight: float | None = None

    def __post_init__(self) -> None:
        object.__setattr__(self, "center", checked_array("center", self.center, (3,)))
        axes = checked_array("axes", self.axes, (3,))
        if np.any(axes <= 0):
            raise ValueError(f"axes: semi-axes must be > 0, got {axes}")
        object.__setattr__(self, "axes", axes)
        R = checked_array("rotation", self.rotation, (3, 3))
        if not np.allclose(R.T @ R, np.eye(3), atol=1e-6):
            raise ValueError("rotation: columns must be orthonormal")
        object.__setattr__(self, "rotation", R)
        if self.kind not in ("occupied", "frontier"):
            raise ValueError(f"kind: must be 'occupied' or 'frontier', got {self.kind!r}")
        if self.gmm_mean is not None:
            object.__setattr__(self, "gmm_mean", checked_array("gmm_mean", self.gmm_mean, (3,)))
        if self.gmm_covariance is not None:
            object.__setattr__(self, "gmm_covariance", checked_array("gmm_covariance", self.gmm_covariance, (3, 3)))

    @property
    def shape_matrix(self) -> NDArray[np.float64]:
        """(3, 3) A with (x - c)^T A (x - c) <= 1 inside."""
        return (self.rotation / self.axes**2) @ self.rotation.T

    def as_quadric(self) -> NDArray[np.float64]:
        """(4, 4) symmetric Q with X^T Q X = 0 on the surface, < 0 inside (X homogeneous)."""
        A = self.shape_matrix
        c = self.center
        Q = np.empty((4, 4))
        Q[:3, :3] = A
        Q[:3, 3] = Q[3, :3] = -A @ c
        Q[3, 3] = c @ A @ c - 1.0
        return Q

    def dual(self) -> NDArray[np.float64]:
        """(4, 4) dual quadric Q* = Q^-1 (up to scale), computed in closed form.

        Q* = T diag(axes^2 R-frame, -1) T^T with T the translation by ``center``.
        """
        Minv = (self.rotation * self.axes**2) @ self.rotation.T
        c = self.center
        Qs = np.empty((4, 4))
        Qs[:3, :3] = Minv - np.outer(c, c)
        Qs[:3, 3] = Qs[3, :3] = -c
        Qs[3, 3] = -1.0
        return Qs

    def contains(self, points: ArrayLike, tol: float = 1e-9) -> NDArray[np.bool_]:
        """(N,) bool for points (N, 3)."""
        d = np.asarray(points, dtype=np.float64) - self.center
        return np.einsum("ni,ij,nj->n", d, self.shape_matrix, d) <= 1.0 + tol

    @property
    def volume(self) -> float:
        return float(4.0 / 3.0 * np.pi * np.prod(self.axes))


# --------------------------------------------------------------------------- planning


@dataclass(frozen=True, eq=False)
class Candidate:
    """One candidate view on the hemisphere.

    index: position in the candidate list of its plan.
    T_world_camera: camera pose, looking at the bounding box centre.
    elevation, azimuth: of the camera position about the box centre (rad).
    parallel: which of the alpha parallels it lies on.
    sector: which of the beta longitude sectors it lies in.
    """

    index: int
    T_world_camera: Pose
    elevation: float
    azimuth: float
    parallel: int
    sector: int

    @property
    def position(self) -> NDArray[np.float64]:
        return self.T_world_camera.translation


@dataclass(frozen=True, eq=False)
class ViewScore:
    """Score of one candidate and why (paper eqs. for W, L-hat, F).

    F = frontier - occupied, each the sum of w * L over ellipsoids of its kind. (For ``projection-zbuffer``,
    ``planner.visibility``: score = frontier = the visible frontier V, occupied = the frontier hidden in this
    view; pixels are raster pixels: a frontier ellipsoid's visible ones, or the frontier ones an occupied
    ellipsoid hides; weights the worth of one such pixel.)
    Per-ellipsoid arrays are indexed like ``PlanResult.ellipsoids``
    (occupied first, then frontier), length E:
    ranks: (E,) int64 depth rank, -1 for ellipsoids that are behind the camera;
    weights: (E,) float64 rank_base**rank (0.5 in the paper; 0 when behind);
    pixels: (E,) float64 L, image pixels inside the projected conic;
    weighted: (E,) float64 L-hat = w * L.
    eligible: the partition rule (and reachability) allow it.
    """

    index: int
    score: float
    frontier: float
    occupied: float
    eligible: bool
    ranks: NDArray[np.int64]
    weights: NDArray[np.float64]
    pixels: NDArray[np.float64]
    weighted: NDArray[np.float64]


@dataclass(frozen=True)
class TourPlan:
    """The ``tour`` planner's predicted tour (``planner.tour``): candidate indices in visit order (the first is the
    plan's next view), the frontier voxels each adds that the views before it do not see, the predicted cumulative
    move seconds from the current state at each view, and how the order was found ("exact" or "lkh")."""

    views: tuple[int, ...]
    gains: tuple[int, ...]
    seconds: tuple[float, ...]
    method: str
    then: tuple[int, ...] = ()
    """Candidate indices the plan after the first view is expected to choose among (the ring's first plan: the other
    side's ring views; ``tour.lookahead``): the move to the first view takes the plate angle and arm configuration
    that also make the quickest of the moves on to them short (:meth:`PlanResult.then_poses`). Empty: none named."""

    @property
    def total_seconds(self) -> float:
        """Predicted move seconds of the whole tour (0 for an empty one)."""
        return self.seconds[-1] if self.seconds else 0.0

    def to_json(self) -> dict[str, object]:
        return {
            "views": list(self.views),
            "gains": list(self.gains),
            "seconds": list(self.seconds),
            "method": self.method,
            "total_seconds": self.total_seconds,
            "then": list(self.then),
        }


@dataclass(frozen=True, eq=False)
class ClusterFit:
    """The model selection of one voxel kind.

    t_chosen: the number of components; bic: (T, BIC) pairs that were evaluated;
    n_points: voxels fitted; seconds: wall time of the fit.
    labels: (n_points,) int32, the cluster of each fitted voxel (in ``VoxelSnapshot`` order of this kind) as
    the index of its ellipsoid among this kind's ellipsoids (``PlanResult.ellipsoids`` order); None when not
    kept.
    """

    kind: EllipsoidKind
    t_chosen: int
    bic: tuple[tuple[int, float], ...]
    n_points: int
    seconds: float = 0.0
    labels: NDArray[np.int32] | None = None


@dataclass(frozen=True, eq=False)
class VoxelSnapshot:
    """Voxel centres by class, for drawing. Each: (N, 3) float64 world frame."""

    resolution: float
    occupied: NDArray[np.float64]
    frontier: NDArray[np.float64]
    unknown: NDArray[np.float64]
    empty: NDArray[np.float64]


@dataclass(frozen=True, eq=False)
class PlanResult:
    """Everything one planning step produced; the UI draws from this alone.

    ellipsoids: occupied ellipsoids first, then frontier.
    scores[i] belongs to candidates[i]. best_index is None when no candidate is eligible.
    sector_edges: (beta,) float64 longitudes (rad) where sectors start.
    timings: seconds per stage ("cluster", "ellipsoids", "candidates", "score", "select").
    ineligible_reasons: (C,) str, see the field.
    """

    iteration: int
    bbox: BoundingBox
    voxels: VoxelSnapshot
    ellipsoids: tuple[Ellipsoid, ...]
    fits: tuple[ClusterFit, ...]
    candidates: tuple[Candidate, ...]
    scores: tuple[ViewScore, ...]
    best_index: int | None
    hemisphere_center: NDArray[np.float64]
    hemisphere_radius: float
    sector_edges: NDArray[np.float64]
    scanned_sectors: frozenset[int]
    eligible_sectors: frozenset[int]
    timings: dict[str, float]
    terminated: str | None = None
    move_costs: NDArray[np.float64] | None = None
    """(C,) seconds the move to each candidate would take (inf = unknown or unreachable), when the selection
    traded F against move time (``selection.move_cost_weight`` > 0); None otherwise."""
    ineligible_reasons: tuple[str, ...] = ()
    """Per candidate, why it is not eligible ("sector locked", "unreachable", "near a taken view"), "" when it
    is; empty for a PlanResult built without them (e.g. an older caller)."""
    tour: TourPlan | None = None
    """The ``tour`` planner's predicted tour from this plan (None for the other planners)."""

    @property
    def best(self) -> Candidate | None:
        return None if self.best_index is None else self.candidates[self.best_index]

    def then_poses(self, index: int | None) -> list[Pose]:
        """``T_world_camera`` of the views the tour expects after candidate ``index`` (``TourPlan.then``) when
        ``index`` is the tour's first view; [] otherwise (another view taken, no tour, none named). What a move to
        ``index`` may plan for (``Cell.move_to(..., then=...)``)."""
        tour = self.tour
        if tour is None or not tour.then or not tour.views or index != tour.views[0]:
            return []
        return [self.candidates[i].T_world_camera for i in tour.then]

    @property
    def occupied_ellipsoids(self) -> tuple[Ellipsoid, ...]:
        return tuple(e for e in self.ellipsoids if e.kind == "occupied")

    @property
    def frontier_ellipsoids(self) -> tuple[Ellipsoid, ...]:
        return tuple(e for e in self.ellipsoids if e.kind == "frontier")


@dataclass(frozen=True, eq=False)
class CameraPath:
    """The camera along one move as the cell expects to run it: where it will be when each frame is taken.

    seconds: the move's duration (s, finite, >= 0). times: (S,) float64 the frames' times since the move started,
    in [0, seconds], increasing (S may be 0: a move too short for a frame). rotations: (S, 3, 3) and translations:
    (S, 3) float64, ``T_world_camera`` (table frame) of each frame.
    """

    seconds: float
    times: NDArray[np.float64]
    rotations: NDArray[np.float64]
    translations: NDArray[np.float64]

    def __post_init__(self) -> None:
        if not (isinstance(self.seconds, int | float) and math.isfinite(self.seconds) and self.seconds >= 0):
            raise ValueError(f"seconds: must be a finite number >= 0, got {self.seconds!r}")
        times = checked_array("times", self.times, (None,))
        n = len(times)
        object.__setattr__(self, "times", times)
        object.__setattr__(self, "rotations", checked_array("rotations", self.rotations, (n, 3, 3)))
        object.__setattr__(self, "translations", checked_array("translations", self.translations, (n, 3)))
        if n and (times[0] < 0 or times[-1] > self.seconds + 1e-9 or np.any(np.diff(times) <= 0)):
            raise ValueError(f"times: must increase within [0, seconds = {self.seconds}], got {times!r}")

    @staticmethod
    def of_poses(seconds: float, times: Sequence[float] | NDArray[np.float64], poses: Sequence[Pose]) -> CameraPath:
        """The path of ``poses`` (``T_world_camera`` each) at ``times`` in a move of ``seconds``."""
        if len(poses) == 0:
            return CameraPath(float(seconds), np.zeros(0), np.zeros((0, 3, 3)), np.zeros((0, 3)))
        return CameraPath(
            float(seconds),
            np.asarray(times, dtype=np.float64),
            np.stack([p.rotation for p in poses]),
            np.stack([p.translation for p in poses]),
        )

    def __len__(self) -> int:
        return len(self.times)

    def poses(self) -> list[Pose]:
        """The frames' ``T_world_camera``."""
        return [Pose.trusted(R, t) for R, t in zip(self.rotations, self.translations, strict=True)]


MovePaths = Callable[[Sequence[Candidate], Sequence[int], float], list[CameraPath | None]]
"""(candidates, K indices, hz) -> per index the path of the move from the current state to that candidate, frames at
``hz`` (:class:`CameraPath`), None when the cell cannot reach it (``devices.cell.Cell.move_paths``)."""
