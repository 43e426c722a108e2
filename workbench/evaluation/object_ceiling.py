"""One reachable-coverage ceiling per (mesh, placement, cell), computed in seconds and cached on disk.

:func:`object_ceiling` builds what :mod:`workbench.evaluation.ceiling` needs from a placed mesh and a cell:
the candidate hemisphere about the mesh's true bounding box, the views the cell can reach
(``cell.is_reachable``, so an arm model replaces the reach sphere without a change here), the
surface samples and probes, and the occlusion scene (object + plate). :func:`cached_ceiling`
keys it by :func:`ceiling_key`: a hash of the placed mesh (so the placement, size and yaw are in
it), the camera, the cell's configuration, the candidate and preprocessing settings and the
ceiling's own settings. Every planner and seed of one (object, placement) shares the result.
"""

from __future__ import annotations

import hashlib
import json
import os
import time
from dataclasses import asdict, dataclass, is_dataclass
from pathlib import Path
from typing import Any, Protocol

import numpy as np
import trimesh
from numpy.typing import NDArray

from devices.config import CameraConfig, CellConfig
from planner.config import PlannerConfig
from planner.types import BoundingBox, Pose
from workbench.evaluation.ceiling import (
    DEFAULT_CEILING,
    CeilingConfig,
    OcclusionScene,
    reachable_views,
    render_ceiling,
    samples_with_normals,
    true_bbox,
    visibility_ceiling,
)

CEILING_VERSION = 3
"""Bumped whenever the computation changes, so old cache entries are not reused."""


@dataclass(frozen=True)
class Ceiling:
    """The reachable-coverage ceiling of one object placement in one cell."""

    coverage: float
    """Fraction of the surface samples covered by the union of the reachable views, in [0, 1]."""
    views: int
    """Reachable candidate views (of ``candidates.count``)."""
    samples: int
    """Surface samples it was measured on."""
    seconds: float
    """Wall time of the computation (not of a cache hit)."""
    key: str
    """The cache key (:func:`ceiling_key`)."""
    cached: bool = False
    """True when read from the cache."""

    def __post_init__(self) -> None:
        if not (np.isfinite(self.coverage) and 0.0 <= self.coverage <= 1.0):
            raise ValueError(f"coverage: must be in [0, 1], got {self.coverage!r}")
        if self.views < 0 or self.samples < 0:
            raise ValueError(f"views, samples: must be >= 0, got {self.views}, {self.samples}")


class ReachCell(Protocol):
    """What the ceiling asks of a cell (a :class:`devices.cell.Cell` is one): its geometry, its arm (its type is
    part of the cache key), the reach predicate and the object box that predicate keeps clear of."""

    arm: Any

    @property
    def config(self) -> CellConfig: ...

    def is_reachable(self, T_table_camera: Pose) -> bool: ...

    def set_object_box(self, bbox: BoundingBox | None) -> None: ...


def _plain(value: Any) -> Any:
    """A JSON-ready form of a config value (dataclasses as dicts, tuples as lists)."""
    if is_dataclass(value) and not isinstance(value, type):
        return {k: _plain(v) for k, v in asdict(value).items()}
    if isinstance(value, tuple | list):
        return [_plain(v) for v in value]
    return value


def ceiling_key(
    mesh: trimesh.Trimesh, cell: ReachCell, camera: CameraConfig, planner: PlannerConfig, config: CeilingConfig
) -> str:
    """sha256 hex of everything the ceiling depends on (the placed mesh's bytes and every setting)."""
    h = hashlib.sha256()
    h.update(np.ascontiguousarray(mesh.vertices, dtype=np.float64).tobytes())
    h.update(np.ascontiguousarray(mesh.faces, dtype=np.int64).tobytes())
    settings = {
        "version": CEILING_VERSION,
        # the reach predicate's inputs: the cell geometry and the arm model (an arm with joint limits and
        # collision geometry instead of the reach sphere must put its parameters in one of these)
        "cell": [type(cell).__name__, type(cell.arm).__name__, _plain(cell.config)],
        "camera": _plain(camera),
        "candidates": _plain(planner.candidates),
        "partitions": _plain(planner.partitions),
        "plate_clearance": planner.preprocess.plate_clearance,
        "ceiling": _plain(config),
    }
    h.update(json.dumps(settings, sort_keys=True, default=repr).encode())
    return h.hexdigest()


def _inputs(
    mesh: trimesh.Trimesh, cell: ReachCell, planner: PlannerConfig, config: CeilingConfig
) -> tuple[list[Any], NDArray[np.float64], NDArray[np.float64]]:
    bbox = true_bbox(mesh)
    cell.set_object_box(bbox)  # an arm keeps clear of the object's (padded) box, as during a scan
    views = reachable_views(bbox, planner, cell.is_reachable)
    samples, normals = samples_with_normals(mesh, config.samples, config.sample_seed)
    return views, samples, normals


def ceiling_mask(
    mesh: trimesh.Trimesh, cell: Any, camera: CameraConfig, planner: PlannerConfig, config: CeilingConfig
) -> tuple[NDArray[np.bool_], int]:
    """((M,) bool covered samples, reachable views) by :func:`workbench.evaluation.ceiling.visibility_ceiling`.

    mesh: the placed object (table frame). cell: anything with ``is_reachable(T_world_camera)``
    and ``config.plate_radius`` / ``config.plate_thickness``.
    """
    views, samples, normals = _inputs(mesh, cell, planner, config)
    n_probes = int(min(config.max_probes, max(1, round(float(mesh.area) / config.probe_spacing**2))))
    probes = samples_with_normals(mesh, n_probes, config.sample_seed + 1)
    scene = OcclusionScene(mesh, cell.config.plate_radius, cell.config.plate_thickness)
    covered = visibility_ceiling(
        scene, samples, normals, views, camera, planner.preprocess.plate_clearance, probes, config
    )
    return covered, len(views)


def reference_mask(
    mesh: trimesh.Trimesh, cell: Any, planner: PlannerConfig, config: CeilingConfig
) -> NDArray[np.bool_]:
    """(M,) bool: the render-based reference on the same samples and views (``cell.camera.render``)."""
    views, samples, _ = _inputs(mesh, cell, planner, config)
    return render_ceiling(cell.camera, samples, views, true_bbox(mesh), planner, config.coverage_radius)


def object_ceiling(
    mesh: trimesh.Trimesh,
    cell: Any,
    camera: CameraConfig,
    planner: PlannerConfig,
    config: CeilingConfig = DEFAULT_CEILING,
) -> Ceiling:
    """The ceiling of ``mesh`` in ``cell`` (computed, not cached)."""
    t0 = time.perf_counter()
    covered, views = ceiling_mask(mesh, cell, camera, planner, config)
    return Ceiling(
        float(covered.mean()),
        views,
        len(covered),
        time.perf_counter() - t0,
        ceiling_key(mesh, cell, camera, planner, config),
    )


def cached_ceiling(
    mesh: trimesh.Trimesh,
    cell: Any,
    camera: CameraConfig,
    planner: PlannerConfig,
    cache_dir: Path | None,
    config: CeilingConfig = DEFAULT_CEILING,
) -> Ceiling:
    """:func:`object_ceiling`, read from ``cache_dir/<key>.json`` when there, else computed and stored.

    cache_dir None: no cache. A corrupt entry is recomputed and overwritten.
    """
    key = ceiling_key(mesh, cell, camera, planner, config)
    path = None if cache_dir is None else Path(cache_dir) / f"{key}.json"
    if path is not None and path.is_file():
        try:
            doc = json.loads(path.read_text())
            return Ceiling(float(doc["coverage"]), int(doc["views"]), int(doc["samples"]), 0.0, key, cached=True)
        except (ValueError, KeyError, TypeError):
            pass  # recompute below
    ceiling = object_ceiling(mesh, cell, camera, planner, config)
    if path is not None:
        path.parent.mkdir(parents=True, exist_ok=True)
        tmp = path.with_name(f"{path.name}.{os.getpid()}.tmp")
        tmp.write_text(json.dumps({"coverage": ceiling.coverage, "views": ceiling.views, "samples": ceiling.samples}))
        os.replace(tmp, path)
    return ceiling
