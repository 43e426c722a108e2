"""The coverage ceiling of an object in a cell, in seconds: the union of every reachable candidate view.

No planner can cover more than this in the same cell with the same candidate hemisphere: the
plate hides the underside and the arm cannot reach every view. The ceiling belongs to the object
and its placement, not to a planner's run: the hemisphere is the one
:func:`planner.candidates.propose_candidates` builds about the object's *true* bounding box, so
every planner and seed of one (object, placement) shares one ceiling.

:func:`visibility_ceiling` computes it without rendering an image. For every reachable candidate
and every surface sample in its frustum and depth range, one ray goes from the camera centre to
the sample; all rays of all views go to open3d in a few batched ``test_occlusions`` calls. A
sample is *seen* by a view when

- it projects inside the image and its planar depth is in ``[min_depth, max_depth]``,
- it is at least ``plate_clearance`` above the plate top (the planner drops lower points),
- the ray reaches it unoccluded (nothing nearer than ``occlusion_tolerance`` before it), and
- the camera samples the surface there densely enough: the pixel footprint on the surface,
  ``z / (f |cos theta|)`` (``theta`` between the ray and the surface normal), is at most
  ``max_footprint`` (only surfaces seen almost edge-on are left out: the union of many views
  fills the gaps one grazing view leaves).

Coverage counts a sample when a scanned point lies within ``coverage_radius`` of it, so a
sample that no view sees directly is still covered next to a seen patch of surface (behind a
silhouette edge, at the foot of the object on the plate). Such a sample is covered when a seen
sample, or a seen *probe*, lies within ``coverage_radius``: probes are a denser sampling of the
surface (``probe_spacing``), cast only near the samples that need them and only until they are
covered. Views are taken in a spread order and a point seen once is not cast again, so most of
the surface drops out after the first few batches.

:func:`render_ceiling` is the reference: it renders every reachable candidate with the
simulated camera, preprocesses the cloud like the planner and counts samples within the coverage
radius of the union. ``tests/workbench/test_ceiling.py`` pins the agreement of the two and
``benchmarks/bench_sweep.py --ceiling`` measures it on the shared models.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import dataclass, replace

import numpy as np
import trimesh
from numpy.typing import NDArray
from scipy.spatial import KDTree

from devices.config import CameraConfig
from planner.candidates import propose_candidates
from planner.config import PlannerConfig, PreprocessConfig
from planner.types import BoundingBox, DepthFrame, Intrinsics, Pose
from planner.validate import finite, integer, require


@dataclass(frozen=True)
class CeilingConfig:
    """How the ceiling is measured (the defaults match ``workbench.evaluation.coverage.coverage`` and ``nbv bench``)."""

    coverage_radius: float = 0.005
    """A sample is covered when a scanned point lies within this distance, metres (as in coverage)."""
    samples: int = 10_000
    """Surface samples the ceiling is measured on (as many as a scan's coverage uses)."""
    sample_seed: int = 0
    """Seed of the ceiling's surface samples: fixed, so every seed of a bench shares one ceiling."""
    occlusion_tolerance: float = 0.001
    """A hit nearer than this before the sample does not hide it (the sample's own triangle), metres."""
    max_footprint: float = 0.04
    """A view counts a point only where one pixel spans at most this much of the surface, metres
    (``z / (f |cos theta|)``). Eight times the coverage radius, not two: one view that sees a slope at a
    grazing angle leaves gaps between its rows of points, but the many neighbouring views that see it
    the same way fill them (with twice the radius, fertility's grazing base was 8 points short of the
    render-based reference; with eight times, suzanne agrees on 99.7 % of samples, not 99.3 %)."""
    probe_spacing: float = 0.0015
    """Mean spacing of the probes, metres: the denser sampling that stands for the seen surface next to a
    sample no view sees (area / spacing^2 probes, at most ``max_probes``)."""
    max_probes: int = 400_000
    """At most this many probes (a huge surface gets a coarser probe spacing)."""
    probe_views: int = 100
    """Probes are cast from at most this many views, spread over the hemisphere (0: every view). A patch
    next to a hidden sample is seen by many views or by none: on the four Stanford models 100 of 400
    views classify as many samples the same as the reference as all 400 do, at half the CPU time."""
    rays_per_batch: int = 50_000
    """Rays per open3d call (bounds the memory: 24 bytes a ray)."""

    def __post_init__(self) -> None:
        for name in ("coverage_radius", "occlusion_tolerance", "probe_spacing", "max_footprint"):
            v = getattr(self, name)
            require(finite(v) and v >= 0, f"ceiling.{name}: must be >= 0, got {v!r}")
        require(self.coverage_radius > 0, f"ceiling.coverage_radius: must be > 0, got {self.coverage_radius!r}")
        require(integer(self.samples) and self.samples >= 1, f"ceiling.samples: must be >= 1, got {self.samples!r}")
        require(integer(self.sample_seed) and self.sample_seed >= 0, "ceiling.sample_seed: must be an integer >= 0")
        require(self.probe_spacing > 0, f"ceiling.probe_spacing: must be > 0, got {self.probe_spacing!r}")
        require(integer(self.max_probes) and self.max_probes >= 1, "ceiling.max_probes: must be an integer >= 1")
        require(integer(self.probe_views) and self.probe_views >= 0, "ceiling.probe_views: must be an integer >= 0")
        require(integer(self.rays_per_batch) and self.rays_per_batch >= 1, "ceiling.rays_per_batch: must be >= 1")


DEFAULT_CEILING = CeilingConfig()
"""The default settings (a module-level value, so function defaults share one instance)."""


def true_bbox(mesh: trimesh.Trimesh) -> BoundingBox:
    """The axis-aligned bounding box of the placed mesh (table frame)."""
    vertices = np.asarray(mesh.vertices, dtype=np.float64)
    return BoundingBox(vertices.min(axis=0), vertices.max(axis=0))


def samples_with_normals(mesh: trimesh.Trimesh, n: int, seed: int) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """(points (n, 3), unit normals (n, 3)) uniform over the surface; the points are those of
    ``devices.mesh.sample_surface(mesh, n, seed)``."""
    sampled = trimesh.sample.sample_surface(mesh, int(n), seed=np.random.default_rng(seed))
    points, faces = sampled[0], sampled[1]
    normals = np.asarray(mesh.face_normals, dtype=np.float64)[np.asarray(faces)]
    return np.asarray(points, dtype=np.float64), normals


def reachable_views(bbox: BoundingBox, config: PlannerConfig, is_reachable: Callable[[Pose], bool]) -> list[Pose]:
    """``T_world_camera`` of every candidate about ``bbox`` that ``is_reachable`` accepts."""
    candidates, _, _ = propose_candidates(bbox, config.candidates, config.partitions)
    return [c.T_world_camera for c in candidates if is_reachable(c.T_world_camera)]


class OcclusionScene:
    """The object and the turntable plate in an open3d RaycastingScene, as the simulated camera sees them.

    mesh: the placed object (table frame). plate_radius, plate_thickness: the plate (radius 0: none).
    """

    def __init__(self, mesh: trimesh.Trimesh, plate_radius: float, plate_thickness: float) -> None:
        import open3d as o3d

        from devices.sim import plate_mesh

        self._scene = o3d.t.geometry.RaycastingScene()
        self._buffers: list[np.ndarray] = []  # from_numpy shares memory: keep the arrays alive with the scene
        parts = [mesh] + ([plate_mesh(plate_radius, plate_thickness)] if plate_radius > 0 else [])
        for part in parts:
            vertices = np.ascontiguousarray(part.vertices, dtype=np.float32)
            faces = np.ascontiguousarray(part.faces, dtype=np.uint32)
            self._buffers += [vertices, faces]
            self._scene.add_triangles(o3d.core.Tensor.from_numpy(vertices), o3d.core.Tensor.from_numpy(faces))

    def blocked(self, rays: NDArray[np.float32]) -> NDArray[np.bool_]:
        """(R,) bool: whether each ray (R, 6) float32 (origin, direction) hits anything for t in (0, 1]."""
        import open3d as o3d

        rays = np.ascontiguousarray(rays, dtype=np.float32)
        return self._scene.test_occlusions(o3d.core.Tensor.from_numpy(rays), tfar=1.0).numpy().astype(bool)


def visibility_ceiling(
    scene: OcclusionScene,
    samples_world: NDArray[np.float64],
    normals_world: NDArray[np.float64],
    views: Sequence[Pose],
    camera: CameraConfig,
    plate_clearance: float,
    probes: tuple[NDArray[np.float64], NDArray[np.float64]],
    config: CeilingConfig = DEFAULT_CEILING,
) -> NDArray[np.bool_]:
    """(M,) bool: which samples the union of ``views`` covers (see the module docstring).

    scene: the object and plate. samples_world, normals_world: (M, 3) float64.
    views: ``T_world_camera`` of the reachable candidates. camera: intrinsics and depth range.
    probes: (points (P, 3), normals (P, 3)), a denser sampling of the same surface: a sample no
    view sees is covered when a seen sample or probe lies within ``coverage_radius`` (only the
    probes near such samples are cast, and only until the sample is covered).
    """
    samples = np.asarray(samples_world, dtype=np.float64)
    normals = np.asarray(normals_world, dtype=np.float64)
    seen = seen_by_any(scene, samples, normals, views, camera, plate_clearance, config)
    covered = seen.copy()
    hidden = np.flatnonzero(~seen)
    if len(hidden) == 0 or not np.any(seen):
        return covered
    r = config.coverage_radius
    close, _ = KDTree(samples[seen]).query(samples[hidden], k=1, distance_upper_bound=r)
    covered[hidden[np.isfinite(close)]] = True  # next to a seen sample: needs no probe
    hidden = hidden[~np.isfinite(close)]
    probe_points, probe_normals = (np.asarray(a, dtype=np.float64) for a in probes)
    usable = np.flatnonzero(probe_points[:, 2] >= plate_clearance)
    if len(hidden) == 0 or len(usable) == 0:
        return covered
    lists = KDTree(probe_points[usable]).query_ball_point(samples[hidden], r)  # probes near each hidden sample
    lengths = np.fromiter((len(x) for x in lists), dtype=np.int64, count=len(lists))
    if lengths.sum() == 0:
        return covered
    pair_sample = np.repeat(np.arange(len(hidden)), lengths)  # (K,) index into hidden
    near = np.concatenate([np.asarray(x, dtype=np.int64) for x in lists if len(x)])  # (K,) index into usable
    mine, pair_probe = np.unique(near, return_inverse=True)  # probes near a hidden sample; (K,) index into mine
    pair_probe = pair_probe.ravel()
    done = np.zeros(len(hidden), dtype=bool)

    def still_needed(seen_probe: NDArray[np.bool_]) -> NDArray[np.bool_]:
        done[pair_sample[seen_probe[pair_probe]]] = True
        needed = np.zeros(len(mine), dtype=bool)
        needed[pair_probe[~done[pair_sample]]] = True
        return needed

    index = usable[mine]
    spread = [views[k] for k in spread_order(len(views))]
    probe_views = spread[: config.probe_views] if config.probe_views else spread
    seen_by_any(
        scene, probe_points[index], probe_normals[index], probe_views, camera, plate_clearance, config, still_needed
    )
    covered[hidden[done]] = True
    return covered


def seen_by_any(
    scene: OcclusionScene,
    points_world: NDArray[np.float64],
    normals_world: NDArray[np.float64],
    views: Sequence[Pose],
    camera: CameraConfig,
    plate_clearance: float,
    config: CeilingConfig = DEFAULT_CEILING,
    still_needed: Callable[[NDArray[np.bool_]], NDArray[np.bool_]] | None = None,
) -> NDArray[np.bool_]:
    """(N,) bool: which surface points (N, 3) with normals (N, 3) at least one view sees directly.

    A point a view has seen is not cast again for later views; the rays of many views go to
    open3d together (``config.rays_per_batch`` at a time). still_needed: called with the seen
    mask after each batch, returns (N,) bool, the points still worth casting (None: the unseen ones).
    """

    points = np.asarray(points_world, dtype=np.float64)
    normals = np.asarray(normals_world, dtype=np.float64)
    seen = np.zeros(len(points), dtype=bool)
    if len(views) == 0 or len(points) == 0:
        return seen
    eyes = np.stack([v.translation for v in views])  # (V, 3)
    R = np.stack([v.rotation for v in views])  # (V, 3, 3) camera -> world
    f = min(camera.fx, camera.fy)
    eligible = points[:, 2] >= plate_clearance
    pending_rays: list[NDArray[np.float32]] = []
    pending_ids: list[NDArray[np.int64]] = []
    pending = 0

    def flush() -> None:
        nonlocal pending, eligible
        if not pending_rays:
            return
        rays = np.concatenate(pending_rays)
        ids = np.concatenate(pending_ids)
        hit = scene.blocked(rays)
        seen[ids[~hit]] = True
        if still_needed is not None:
            eligible &= still_needed(seen)
        pending_rays.clear()
        pending_ids.clear()
        pending = 0

    for k in spread_order(len(views)):
        todo = np.flatnonzero(~seen & eligible)
        if len(todo) == 0:
            break
        d_world = points[todo] - eyes[k]  # (T, 3) eye -> point
        p_cam = d_world @ R[k]  # (T, 3): R^T d
        z = p_cam[:, 2]
        ok = (z >= camera.min_depth) & (z <= camera.max_depth)
        with np.errstate(divide="ignore", invalid="ignore"):
            u = camera.fx * p_cam[:, 0] / z + camera.cx
            v = camera.fy * p_cam[:, 1] / z + camera.cy
        ok &= (u >= -0.5) & (u < camera.width - 0.5) & (v >= -0.5) & (v < camera.height - 0.5)
        dist = np.linalg.norm(d_world, axis=1)
        cos = np.abs(np.einsum("ij,ij->i", d_world, normals[todo])) / np.maximum(dist, 1e-12)
        ok &= z <= config.max_footprint * f * cos  # the pixel footprint z / (f cos) on the surface
        ok &= dist > config.occlusion_tolerance
        if not np.any(ok):
            continue
        idx = todo[ok]
        scale = (1.0 - config.occlusion_tolerance / dist[ok])[:, None]  # t = 1 stops tolerance before the point
        rays = np.empty((len(idx), 6), dtype=np.float32)
        rays[:, :3] = eyes[k]
        rays[:, 3:] = d_world[ok] * scale
        pending_rays.append(rays)
        pending_ids.append(idx)
        pending += len(idx)
        if pending >= config.rays_per_batch:
            flush()
    flush()
    return seen


def spread_order(n: int) -> list[int]:
    """0..n-1 in an order whose every prefix is spread over the whole range (bit-reversal-like
    stride), so the first views cast already see most of the surface and its points drop out."""
    if n <= 2:
        return list(range(n))
    step = max(1, round(n * 0.6180339887))
    while np.gcd(step, n) != 1:
        step += 1
    return [(k * step) % n for k in range(n)]


def view_coverage(
    depth: NDArray[np.float32],
    pose: Pose,
    intrinsics: Intrinsics,
    samples_world: NDArray[np.float64],
    bbox: BoundingBox,
    preprocess_config: PreprocessConfig,
    coverage_radius: float = 0.005,
) -> NDArray[np.bool_]:
    """(M,) bool: the samples one rendered view covers: its depth (H, W) at ``pose`` (``T_world_camera``)
    preprocessed like the planner's frames (cropped to ``bbox``, plate removed, down-sampled, ``preprocess_config``'s
    filters), a sample covered within ``coverage_radius`` (m) of the cloud. samples_world: (M, 3) float64."""
    from planner.preprocess import preprocess

    samples = np.asarray(samples_world, dtype=np.float64)
    points = preprocess(DepthFrame(depth, pose, intrinsics).points_world, bbox, preprocess_config)
    if len(points) == 0 or len(samples) == 0:
        return np.zeros(len(samples), dtype=bool)
    dist, _ = KDTree(points).query(samples, k=1, distance_upper_bound=coverage_radius)
    return np.isfinite(dist)


def render_ceiling(
    camera: object,
    samples_world: NDArray[np.float64],
    views: Sequence[Pose],
    bbox: BoundingBox,
    config: PlannerConfig,
    coverage_radius: float = 0.005,
) -> NDArray[np.bool_]:
    """(M,) bool: the reference: render every view, preprocess its cloud like the planner (cropped to
    ``bbox``, plate removed, down-sampled; no outlier removal), and count samples within
    ``coverage_radius`` of the union (:func:`view_coverage` of each view, on the samples not covered yet). camera:
    a simulated camera (``render(T_world_camera)`` gives noise-free depth, ``intrinsics``). samples_world: (M, 3)
    float64."""
    samples = np.asarray(samples_world, dtype=np.float64)
    clean = replace(config.preprocess, outlier_min_neighbors=0)
    covered = np.zeros(len(samples), dtype=bool)
    for pose in views:
        todo = np.flatnonzero(~covered)
        if len(todo) == 0:
            break
        depth = camera.render(pose)  # type: ignore[attr-defined]
        seen = view_coverage(depth, pose, camera.intrinsics, samples[todo], bbox, clean, coverage_radius)  # type: ignore[attr-defined]
        covered[todo[seen]] = True
    return covered
