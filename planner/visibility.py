"""The visible-frontier score V of the ``projection-zbuffer`` evaluator (a departure from §III-E).

For each candidate view, every ellipsoid of both kinds is rasterised with its per-pixel depth
(``planner.zbuffer``, a ``w x h`` raster). For every raster pixel:

- ``z_o`` = depth of the nearest occupied ellipsoid along the pixel's ray (inf if none),
- ``z_f`` = depth of the nearest frontier ellipsoid (inf if none);

the pixel shows frontier when ``z_f < inf`` and ``z_f <= z_o + tol``: the frontier is in
front of every occupied ellipsoid. ``tol`` (``zbuffer.depth_tolerance_voxels`` voxels)
absorbs that frontier voxels are by definition next to occupied ones, so their ellipsoids
and the occupied ones interpenetrate by about a voxel. Then::

    V = sum over frontier pixels of  w_e      (e: the nearest frontier ellipsoid of the pixel)

with ``w_e`` a per-ellipsoid weight (1 by default; see ``frontier_weights``). Unlike the paper's
``F = sum w L (frontier) - sum w L (occupied)``, V does not go down with the occupied surface in
view: after every sector is scanned and the frontier left is behind the object, F rewards views
that see little of the object, V still follows the frontier that a view can reach.

``ViewScore`` per-ellipsoid terms (length E, order of ``ellipsoids``):

- ``pixels[e]``: frontier e: the frontier pixels it owns (it is the nearest frontier there);
  occupied e: the frontier pixels it hides (it is the nearest occupied one in front of them);
- ``weights[e]``: ``w_e`` (occupied: the mean weight of the frontier they hide, 0 if none);
- ``weighted[e] = weights[e] * pixels[e]``; ``score = frontier = sum over frontier ellipsoids``,
  ``occupied = sum over occupied ellipsoids``, the weighted frontier pixels hidden in this view;
- ``ranks[e]``: depth rank of the centre, as in ``planner.scoring`` (for the inspector only).
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike, NDArray

from planner.config import ZBufferConfig
from planner.scoring import depth_ranks, view_scores
from planner.types import Candidate, Ellipsoid, Intrinsics, Pose, ViewScore
from planner.zbuffer import Fragments, rasterize


@dataclass(frozen=True, eq=False)
class FrontierPixels:
    """The K raster pixels (over all C cameras) that some frontier ellipsoid covers.

    camera: (K,) int64; pixel: (K,) int64 raster pixel ``j * w + i``;
    frontier_owner: (K,) int64 the nearest frontier ellipsoid, frontier_depth: (K,) float64 its depth;
    occupied_owner: (K,) int64 the nearest occupied ellipsoid (-1: none), occupied_depth: (K,) float64 (inf: none);
    visible: (K,) bool, the pixel shows frontier (``z_f <= z_o + tol``).
    """

    camera: NDArray[np.int64]
    pixel: NDArray[np.int64]
    frontier_owner: NDArray[np.int64]
    frontier_depth: NDArray[np.float64]
    occupied_owner: NDArray[np.int64]
    occupied_depth: NDArray[np.float64]
    visible: NDArray[np.bool_]


_DEPTH_STEP = 1e-4
"""Depths are compared in steps of 0.1 mm (up to 6.5 m): depth and ellipsoid index go into one uint32 key per
fragment, so one ``np.minimum.at`` finds both the nearest depth and its ellipsoid (ties go to the lower index)."""
_INDEX_BITS = 16
_NONE = np.iinfo(np.uint32).max


def _keys(frags: Fragments, select: NDArray[np.bool_]) -> NDArray[np.uint32]:
    steps = np.minimum(np.rint(frags.depth[select] / _DEPTH_STEP), (1 << (32 - _INDEX_BITS)) - 2)
    key = steps.astype(np.uint32) << np.uint32(_INDEX_BITS)
    return key | frags.ellipsoid[select].astype(np.uint32)


def _decode(best: NDArray[np.uint32]) -> tuple[NDArray[np.float64], NDArray[np.int64]]:
    found = best != _NONE
    depth = np.where(found, (best >> _INDEX_BITS) * _DEPTH_STEP, np.inf)
    return depth, np.where(found, (best & ((1 << _INDEX_BITS) - 1)).astype(np.int64), -1)


def frontier_pixels(frags: Fragments, is_frontier: NDArray[np.bool_], depth_tolerance: float) -> FrontierPixels:
    """Nearest frontier and occupied ellipsoid at every pixel a frontier ellipsoid covers (module docstring).

    is_frontier: (E,) bool. Frontier ellipsoids that contain the camera take no part (their voxels are
    not in front of it).
    """
    n_pix = frags.width * frags.height
    gid = frags.camera * n_pix + frags.pixel
    kind_f = is_frontier[frags.ellipsoid]
    sel_f = kind_f & ~frags.inside[frags.camera, frags.ellipsoid]
    gid_f, key_f = gid[sel_f], _keys(frags, sel_f)
    best = np.full(frags.n_cameras * n_pix, _NONE, dtype=np.uint32)
    np.minimum.at(best, gid_f, key_f)
    owner = key_f == best[gid_f]  # one fragment per covered pixel: keys are unique per pixel
    gid_k = gid_f[owner]
    z_f, own_f = _decode(key_f[owner])
    slot = np.full(frags.n_cameras * n_pix, -1, dtype=np.int32)
    slot[gid_k] = np.arange(len(gid_k))
    s_o = slot[gid[~kind_f]]
    keep = s_o >= 0
    best_o = np.full(len(gid_k), _NONE, dtype=np.uint32)
    np.minimum.at(best_o, s_o[keep], _keys(frags, ~kind_f)[keep])
    z_o, own_o = _decode(best_o)
    visible = z_f <= z_o + depth_tolerance
    return FrontierPixels(gid_k // n_pix, gid_k % n_pix, own_f, z_f, own_o, z_o, visible)


def _checked(
    ellipsoids: Sequence[Ellipsoid],
    candidates: Sequence[Candidate],
    intrinsics: Intrinsics,
    config: ZBufferConfig,
    eligible: ArrayLike,
    resolution: float,
    frontier_weights: ArrayLike | None,
) -> tuple[NDArray[np.bool_], NDArray[np.float64]]:
    for i, e in enumerate(ellipsoids):
        if not isinstance(e, Ellipsoid):
            raise ValueError(f"ellipsoids[{i}]: expected an Ellipsoid, got {type(e).__name__}")
    for i, c in enumerate(candidates):
        if not isinstance(c, Candidate):
            raise ValueError(f"candidates[{i}]: expected a Candidate, got {type(c).__name__}")
    if len(ellipsoids) >= 1 << _INDEX_BITS:
        raise ValueError(f"ellipsoids: at most {(1 << _INDEX_BITS) - 1}, got {len(ellipsoids)}")
    if not isinstance(intrinsics, Intrinsics):
        raise ValueError(f"intrinsics: expected an Intrinsics, got {type(intrinsics).__name__}")
    if not isinstance(config, ZBufferConfig):
        raise ValueError(f"config: expected a ZBufferConfig, got {type(config).__name__}")
    if isinstance(resolution, bool) or not np.isfinite(resolution) or resolution <= 0:
        raise ValueError(f"resolution: must be a finite number > 0, got {resolution!r}")
    mask = np.asarray(eligible)
    if mask.shape != (len(candidates),):
        raise ValueError(f"eligible: expected shape ({len(candidates)},), got {mask.shape}")
    if mask.size and mask.dtype != np.bool_:
        raise ValueError(f"eligible: expected a bool array, got dtype {mask.dtype}")
    if frontier_weights is None:
        weights = np.ones(len(ellipsoids))
    else:
        weights = np.asarray(frontier_weights, dtype=np.float64)
        if weights.shape != (len(ellipsoids),):
            raise ValueError(f"frontier_weights: expected shape ({len(ellipsoids)},), got {weights.shape}")
        if not np.all(np.isfinite(weights)) or np.any(weights < 0):
            raise ValueError("frontier_weights: must be finite and >= 0")
    return mask.astype(bool), weights


def score_visible_frontier(
    ellipsoids: Sequence[Ellipsoid],
    candidates: Sequence[Candidate],
    intrinsics: Intrinsics,
    config: ZBufferConfig,
    eligible: ArrayLike,
    resolution: float,
    frontier_weights: ArrayLike | None = None,
) -> tuple[ViewScore, ...]:
    """Score every candidate (C) by its visible frontier V -> C ViewScores, in candidate order.

    resolution: voxel edge, metres (scales ``config.depth_tolerance_voxels``).
    frontier_weights: (E,) float64 ``w_e`` >= 0 per ellipsoid (only frontier entries are used); None: all 1.
    eligible: (C,) bool, copied into ``ViewScore.eligible``; it does not change any score.
    """
    mask, weights = _checked(ellipsoids, candidates, intrinsics, config, eligible, resolution, frontier_weights)
    if not candidates:
        return ()
    poses = [c.T_world_camera for c in candidates]
    C, E = len(candidates), len(ellipsoids)
    is_frontier = np.array([e.kind == "frontier" for e in ellipsoids], dtype=bool)
    frags = rasterize(ellipsoids, poses, intrinsics, config.width, config.height, focus=is_frontier)
    px = frontier_pixels(frags, is_frontier, config.depth_tolerance_voxels * resolution)
    shown = px.visible
    hidden = ~shown
    hidden_at = px.camera[hidden] * E + px.occupied_owner[hidden]
    pixels = np.bincount(px.camera[shown] * E + px.frontier_owner[shown], minlength=C * E).astype(np.float64)
    pixels += np.bincount(hidden_at, minlength=C * E)
    # occupied e: the total weight of the frontier it hides
    pixels = pixels.reshape(C, E)
    w = np.where(is_frontier[None, :], weights[None, :], 0.0) * np.ones((C, 1))
    if config.measure == "voxels":  # a frontier pixel stands for its ellipsoid's voxels / the pixels it covers
        sel = is_frontier[frags.ellipsoid] & ~frags.inside[frags.camera, frags.ellipsoid]
        covered = np.bincount(frags.camera[sel] * E + frags.ellipsoid[sel], minlength=C * E).reshape(C, E)
        n_points = np.array([float(e.n_points) for e in ellipsoids])
        w *= np.divide(n_points[None, :], covered, out=np.zeros((C, E)), where=covered > 0)
    per_pixel = w[px.camera[hidden], px.frontier_owner[hidden]]  # the weight of each hidden frontier pixel
    hidden_weight = np.bincount(hidden_at, weights=per_pixel, minlength=C * E).astype(float).reshape(C, E)
    w[:, ~is_frontier] = np.divide(
        hidden_weight[:, ~is_frontier],
        pixels[:, ~is_frontier],
        out=np.zeros_like(hidden_weight[:, ~is_frontier]),
        where=pixels[:, ~is_frontier] > 0,
    )
    weighted = w * pixels
    frontier = weighted[:, is_frontier].sum(axis=1)
    occupied = weighted[:, ~is_frontier].sum(axis=1)
    ranks = depth_ranks(frags.center_depth) if E else np.zeros((C, 0), dtype=np.int64)
    for a in (ranks, w, pixels, weighted):
        a.setflags(write=False)
    score = frontier + config.hidden_weight * occupied
    return view_scores(candidates, mask, score, frontier, occupied, ranks, w, pixels, weighted)


@dataclass(frozen=True, eq=False)
class ZBufferImage:
    """The raster of one candidate, for the inspector (h, w images, row j = raster row, column i).

    frontier_owner, occupied_owner: (h, w) int64 nearest ellipsoid of each kind (index into the
    ellipsoids), -1 for none; frontier_depth, occupied_depth: (h, w) float64, metres, inf for none;
    visible: (h, w) bool, the pixel counts in V.
    """

    frontier_owner: NDArray[np.int64]
    occupied_owner: NDArray[np.int64]
    frontier_depth: NDArray[np.float64]
    occupied_depth: NDArray[np.float64]
    visible: NDArray[np.bool_]


def zbuffer_image(
    ellipsoids: Sequence[Ellipsoid],
    T_world_camera: Pose,
    intrinsics: Intrinsics,
    config: ZBufferConfig,
    resolution: float,
) -> ZBufferImage:
    """The rasterised z-buffers of one view ``T_world_camera`` (what V counts), as images."""
    if not isinstance(config, ZBufferConfig):
        raise ValueError(f"config: expected a ZBufferConfig, got {type(config).__name__}")
    if isinstance(resolution, bool) or not np.isfinite(resolution) or resolution <= 0:
        raise ValueError(f"resolution: must be a finite number > 0, got {resolution!r}")
    is_frontier = np.array([e.kind == "frontier" for e in ellipsoids], dtype=bool)
    frags = rasterize(ellipsoids, [T_world_camera], intrinsics, config.width, config.height)
    n_pix = config.width * config.height
    images = []
    for select in (is_frontier[frags.ellipsoid] & ~frags.inside[0, frags.ellipsoid], ~is_frontier[frags.ellipsoid]):
        best = np.full(n_pix, _NONE, dtype=np.uint32)
        np.minimum.at(best, frags.pixel[select], _keys(frags, select))
        images.append(_decode(best))
    (z_f, own_f), (z_o, own_o) = images
    visible = np.isfinite(z_f) & (z_f <= z_o + config.depth_tolerance_voxels * resolution)
    shape = (config.height, config.width)
    return ZBufferImage(
        own_f.reshape(shape), own_o.reshape(shape), z_f.reshape(shape), z_o.reshape(shape), visible.reshape(shape)
    )
