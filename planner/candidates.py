"""Candidate views on a partial hemisphere about the bounding box (paper §III-B).

The hemisphere is centred on B's centre with radius ``R = d_c + d_b``: ``d_c`` the
camera's working distance, ``d_b`` half of B's diagonal, so every point of B is
at least ``d_c`` from every candidate (and in front of it: B lies in the ball of
radius ``d_b`` around the centre, which sits at depth ``R`` on the optical axis).
The box is B for the paper; with ``candidates.aim = "content"`` the planner passes the box of its
OCCUPIED and FRONTIER voxels instead (``Planner.candidate_box``), and "B" below means that box.

Layout (documented choices where the paper gives none):

- ``alpha`` parallels at equidistant elevations from ``min_elevation_deg`` to
  ``max_elevation_deg``, both ends included (with ``alpha == 1``: their midpoint).
  The lowest elevation keeps the camera above the turntable: it is the knob for that,
  nothing here clips against the plate.
- ``N`` views shared out in proportion to each parallel's length (``cos elevation``)
  by largest-remainder rounding, so exactly ``N`` in total (remainder ties go to the
  lower parallel). A short parallel may get no view at all.
- On a parallel with ``n`` views the azimuths are ``2 pi j / n``, odd parallels shifted
  by half a step so neighbouring parallels interleave.
- Order: parallel by parallel from the lowest, by increasing azimuth index ``j``.
- Every camera looks at B's centre (``Pose.look_at``, world z up).
"""

from __future__ import annotations

import math
import threading
from collections.abc import Sequence

import numpy as np
from numpy.typing import NDArray

from planner.config import CandidateConfig, PartitionConfig
from planner.partitions import sector_of
from planner.types import BoundingBox, Candidate, Pose


def parallel_elevations(config: CandidateConfig) -> NDArray[np.float64]:
    """(alpha,) float64: elevations (rad) of the parallels, lowest first, ends inclusive."""
    lo, hi = math.radians(config.min_elevation_deg), math.radians(config.max_elevation_deg)
    if config.parallels == 1:
        return np.array([0.5 * (lo + hi)])
    return np.linspace(lo, hi, config.parallels)


def share_out(total: int, weights: NDArray[np.float64]) -> NDArray[np.int64]:
    """(K,) int64 counts summing to ``total``, proportional to ``weights`` (K,) >= 0.

    Largest-remainder (Hamilton) rounding: floor every quota, then give the
    leftover units to the largest fractional parts (ties: lower index first).
    """
    w = np.asarray(weights, dtype=np.float64)
    if w.ndim != 1 or w.size == 0 or not np.all(np.isfinite(w)) or np.any(w < 0) or w.sum() <= 0:
        raise ValueError(f"weights: need a non-empty 1-D array of finite values >= 0 with a positive sum, got {w}")
    if not isinstance(total, int | np.integer) or total < 0:
        raise ValueError(f"total: must be an integer >= 0, got {total!r}")
    quota = total * w / w.sum()
    counts = np.floor(quota).astype(np.int64)
    # floating error could push a floor one past the quota sum; never hand out more than total
    while counts.sum() > total:
        counts[int(np.argmax(counts - quota))] -= 1
    leftover = total - int(counts.sum())
    order = np.lexsort((np.arange(w.size), -(quota - counts)))  # largest remainder, then lowest index
    counts[order[:leftover]] += 1
    return counts


MIN_STANDOFF = 0.05
"""A range-limited sensor's candidates stay at least this far outside B's enclosing sphere, metres."""


def held_aim(previous: BoundingBox | None, box: BoundingBox, tolerance: float) -> BoundingBox:
    """The box the candidate sphere is built about after a frame: ``previous`` while every face of the new ``box`` lies
    within ``tolerance`` (metres) of its own, else ``box`` (also with no ``previous``, or ``tolerance`` 0).

    The held box is compared with the new one, not with the one before, so the aim never drifts more than
    ``tolerance`` from the content box, however many small steps it takes (``candidates.aim_hold_voxels``)."""
    if previous is None or tolerance <= 0:
        return box
    moved = max(float(np.max(np.abs(box.lower - previous.lower))), float(np.max(np.abs(box.upper - previous.upper))))
    return previous if moved <= tolerance else box


def sphere_radius(config: CandidateConfig, half_diagonal: float) -> float:
    """R of the candidate sphere about B's centre for B's half-diagonal ``d_b``: the paper's ``d_c + d_b``, cut
    so that B's far corner (``R + d_b`` from the camera) stays within the sensor's ``max_range`` (a D405 ends at
    0.5 m: from the paper's R its far side returns nothing), but never closer than ``d_b + MIN_STANDOFF``."""
    radius = float(config.working_distance + half_diagonal)
    if config.max_range > 0 and radius + half_diagonal > config.max_range:
        radius = max(float(config.max_range) - half_diagonal, half_diagonal + MIN_STANDOFF)
    return radius


def propose_candidates(
    bbox: BoundingBox, config: CandidateConfig, partitions: PartitionConfig
) -> tuple[tuple[Candidate, ...], NDArray[np.float64], float]:
    """The candidate views for bounding box ``bbox``.

    Returns (candidates, center (3,) float64, radius): ``config.count`` candidates in
    the order described in the module docstring, ``candidates[i].index == i``. The same box, config and partitions
    give the same (immutable) objects: the last sets are kept.
    """
    if not isinstance(bbox, BoundingBox):
        raise ValueError(f"bbox: expected a BoundingBox, got {type(bbox).__name__}")
    if not isinstance(config, CandidateConfig):
        raise ValueError(f"config: expected a CandidateConfig, got {type(config).__name__}")
    if not isinstance(partitions, PartitionConfig):
        raise ValueError(f"partitions: expected a PartitionConfig, got {type(partitions).__name__}")
    key = (np.asarray(bbox.lower).tobytes(), np.asarray(bbox.upper).tobytes(), config, partitions)
    hit = _RECENT.get(key)
    if hit is not None:
        return hit
    out = _proposed(bbox, config, partitions)
    with _RECENT_LOCK:  # planners in several threads share the sets
        while len(_RECENT) >= _RECENT_SIZE:
            _RECENT.pop(next(iter(_RECENT)))  # the oldest
        _RECENT[key] = out
    return out


_RECENT_SIZE = 16
_RECENT_LOCK = threading.Lock()
_RECENT: dict[tuple[bytes, bytes, CandidateConfig, PartitionConfig], tuple[tuple[Candidate, ...], NDArray, float]] = {}
"""The last candidate sets by (box, config, partitions): a plan whose box is held (``candidates.aim_hold_voxels``)
or unchanged gets the same (immutable) candidates without building 400 poses again."""


def _proposed(
    bbox: BoundingBox, config: CandidateConfig, partitions: PartitionConfig
) -> tuple[tuple[Candidate, ...], NDArray[np.float64], float]:
    center = np.array(bbox.center, dtype=np.float64)
    radius = sphere_radius(config, 0.5 * bbox.diagonal)
    elevations = parallel_elevations(config)
    counts = share_out(config.count, np.cos(elevations))

    eyes: list[NDArray[np.float64]] = []
    layout: list[tuple[float, float, int]] = []  # (elevation, azimuth, parallel) per candidate
    for p, (elev, n) in enumerate(zip(elevations, counts, strict=True)):
        n = int(n)
        if n == 0:
            continue
        step = 2.0 * math.pi / n
        shift = 0.5 * step if p % 2 else 0.0
        azimuths = shift + step * np.arange(n)  # < 2 pi by construction
        ce, se = math.cos(elev), math.sin(elev)
        eyes.append(center + radius * np.column_stack([ce * np.cos(azimuths), ce * np.sin(azimuths), np.full(n, se)]))
        layout += [(float(elev), float(a), p) for a in azimuths]
    poses = Pose.look_at_many(np.concatenate(eyes), center)
    candidates = [
        Candidate(
            index=i,
            T_world_camera=pose,
            elevation=elev,
            azimuth=azimuth,
            parallel=p,
            sector=sector_of(azimuth, partitions),
        )
        for i, (pose, (elev, azimuth, p)) in enumerate(zip(poses, layout, strict=True))
    ]
    center.setflags(write=False)
    return tuple(candidates), center, radius


LOOK_POINT_MIN_SPREAD = 0.05
"""The given views' optical axes must span at least this (the smallest eigenvalue of ``sum(I - d d^T)`` per view,
about sin^2 of the angle between near-parallel axes) for the point they pass nearest to be their centre."""


def look_point(poses: Sequence[Pose]) -> NDArray[np.float64] | None:
    """(3,) the point the optical axes of ``poses`` pass nearest (least squares), None when the axes are about
    parallel (no such point, or one far off: :data:`LOOK_POINT_MIN_SPREAD`).

    Each axis is the line through the camera along its +z; the squared distance of x from it is
    ``|(I - d d^T)(x - t)|^2``, so the point minimising the sum solves ``sum(I - d d^T) x = sum(I - d d^T) t``.
    """
    A = np.zeros((3, 3))
    b = np.zeros(3)
    for pose in poses:
        d = pose.rotation[:, 2]
        M = np.eye(3) - np.outer(d, d)
        A += M
        b += M @ pose.translation
    if len(poses) < 2 or np.linalg.eigvalsh(A)[0] < LOOK_POINT_MIN_SPREAD:
        return None
    return np.asarray(np.linalg.solve(A, b), dtype=np.float64)


def candidates_from_poses(
    poses: Sequence[Pose], bbox: BoundingBox, partitions: PartitionConfig
) -> tuple[tuple[Candidate, ...], NDArray[np.float64], float]:
    """Given views as candidates (a recorded set's, in the order given), described about the point they look at
    like the hemisphere's about its centre: (candidates, centre (3,), radius = the mean distance of the views from
    the centre). Each candidate's ``parallel`` is 0 (given views lie on no parallel); its sector is that of its
    azimuth.

    The centre is :func:`look_point` of the views (the object they surround), ``bbox``'s centre only when their
    axes are about parallel. Not B's centre, as for the hemisphere: after the first frame B has grown along that
    view (paper §III-C) and its centre lies behind the object (16 cm behind the Stanford bunny), and azimuths
    about it put a view a quarter turn round the object into the first view's own sector.
    The hemisphere is built about B's centre, so its azimuths are consistent with it; given views are not.
    ValueError for no poses."""
    if not poses:
        raise ValueError("candidate poses: none given")
    for i, pose in enumerate(poses):
        if not isinstance(pose, Pose):
            raise ValueError(f"candidate poses[{i}]: expected a Pose, got {type(pose).__name__}")
    looked_at = look_point(poses)
    center = np.array(bbox.center if looked_at is None else looked_at, dtype=np.float64)
    out = []
    distances = []
    for i, pose in enumerate(poses):
        d = pose.translation - center
        distance = float(np.linalg.norm(d))
        distances.append(distance)
        azimuth = math.atan2(d[1], d[0]) % (2 * math.pi)
        elevation = math.asin(max(-1.0, min(1.0, d[2] / distance))) if distance > 0 else 0.0
        out.append(Candidate(i, pose, elevation, azimuth, 0, sector_of(azimuth, partitions)))
    return tuple(out), center, float(np.mean(distances))
