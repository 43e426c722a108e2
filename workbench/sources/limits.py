"""Admission limits: what a request may ask of the server, checked before any heavy work (422 / 413 beyond them).

``PlannerConfig`` only refuses values that make no sense (a negative resolution); a request could still ask for
a 1e-9 m voxel grid, a billion candidates or a floor at 1e308 m and exhaust the server's memory or time, or
overflow downstream. Every numeric field a request can set has a range here (:data:`BOUNDS`, documented in
docs/reliability.md), and a few products bound the cost of one plan (grid cells, the BIC search's fits,
candidates x ellipsoids). A mesh is bounded by what ray casting and loading cost (:class:`MeshLimits`): its
triangles after triangulation, vertices, polygon degree and triangles per vertex (a "fan bomb" of a few
vertices and millions of overlapping triangles). An OBJ or OFF file is pre-scanned as text before trimesh
loads it, so a bomb is refused before it takes memory. The operator's own TOML config is not bounded.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np

from planner import PlannerConfig
from planner.bbox import max_voxels
from workbench.errors import Invalid, TooLarge
from workbench.sources.mesh_prescan import gltf_counts, gltf_json, ply_counts

MAX_GRID_CELLS_PER_AXIS = 300
"""``voxel.max_extent / voxel.resolution`` at most this: a grid of at most 300^3 = 27 M voxels."""
MAX_EXHAUSTIVE_FITS = 60
"""``cluster.search = "exhaustive"`` fits every T in [t_min, t_max]: at most this many."""
MAX_CANDIDATE_TERMS = 100_000
"""``candidates.count * 2 * cluster.t_max`` (every candidate projects every ellipsoid) at most this."""
SERVER_BYTES_PER_VOXEL = 60
"""What one voxel of a live session's grid costs the server process, bytes (its map, the planner's voxel lists and
the plan it holds; measured by benchmarks/bench_session_memory.py, rounded up)."""

BOUNDS: dict[str, tuple[float, float]] = {
    "voxel.resolution": (0.001, 0.2),
    "voxel.gamma": (0.0, 0.5),
    "voxel.max_extent": (0.01, 3.0),
    "voxel.initial_diagonal_factor": (1.0, 10.0),
    "voxel.floor_height": (-1.0, 1.0),
    "cluster.t_min": (1, 200),
    "cluster.t_max": (1, 200),
    "cluster.min_points_per_component": (1, 10_000),
    "cluster.max_iter": (1, 1000),
    "cluster.tol": (1e-8, 1.0),
    "cluster.reg_covar_voxels": (1e-6, 100.0),
    "cluster.seed": (0, 2**32 - 1),
    "candidates.count": (1, 5000),
    "candidates.parallels": (1, 200),
    "candidates.working_distance": (0.01, 5.0),
    "candidates.min_elevation_deg": (-90.0, 90.0),
    "candidates.max_elevation_deg": (-90.0, 90.0),
    "scoring.rank_base": (0.0, 1.0),
    "partitions.sectors": (1, 360),
    "partitions.offset_deg": (-360.0, 360.0),
    "partitions.revisit_deg": (0.0, 360.0),
    "termination.max_views": (1, 500),
    "termination.growth_threshold": (0.0, 100.0),
    "preprocess.outlier_min_neighbors": (0, 200),
    "preprocess.outlier_radius": (0.0, 0.1),
    "preprocess.workspace_radius": (0.0, 5.0),
    "preprocess.workspace_height": (0.0, 5.0),
    "preprocess.crop_margin": (0.0, 1.0),
    "preprocess.plate_clearance": (0.0, 0.1),
    "preprocess.downsample": (0.0, 0.1),
    "preprocess.support_min_points": (0, 1000),
    "preprocess.support_voxel": (0.0, 0.1),
    "noise.depth_std": (0.0, 0.05),
    "noise.depth_z2": (0.0, 0.1),
    "noise.plate_sigmas": (0.0, 20.0),
    "noise.icp_sigmas": (0.0, 20.0),
    "noise.plate_fit_window": (0.0, 0.1),
    "noise.flying_jump": (0.0, 1.0),
    "noise.dropout_fill_px": (0, 100),
    "registration.max_correspondence": (0.0, 0.5),
    "registration.max_iterations": (1, 500),
    "registration.min_fitness": (0.0, 1.0),
    "registration.max_rmse": (0.0, 0.5),
    "registration.max_correction": (0.0, 1.0),
}
"""Inclusive [low, high] of every numeric config field accepted over the API."""


def grid_voxels(config: PlannerConfig) -> int:
    """The most voxels a session's map can hold: its box grows to ``voxel.max_extent`` per edge."""
    n = max_voxels(config.voxel.max_extent, config.voxel.resolution)
    return n * n * n


def check_config(config: PlannerConfig, max_session_voxels: int = 0, max_live_sessions: int = 0) -> None:
    """Invalid (422) naming the first field outside ``BOUNDS`` or the first cost product over its limit.

    max_session_voxels: the server's voxel budget per session (``server.max_session_voxels``; 0: none), which
    bounds what a live session costs the server (:data:`SERVER_BYTES_PER_VOXEL`); max_live_sessions: the
    server's limit, quoted in the refusal (what the budget is derived from)."""
    for name, (low, high) in BOUNDS.items():
        section, key = name.split(".")
        value = getattr(getattr(config, section), key)
        if not low <= value <= high:
            raise Invalid(f"config: {name} must be in [{low:g}, {high:g}] over the API, got {value!r}")
    cells = config.voxel.max_extent / config.voxel.resolution
    if cells > MAX_GRID_CELLS_PER_AXIS:
        raise Invalid(
            f"config: voxel.max_extent / voxel.resolution = {cells:.0f} voxels per axis, "
            f"more than {MAX_GRID_CELLS_PER_AXIS} (coarser resolution or smaller max_extent)"
        )
    voxels = grid_voxels(config)
    if max_session_voxels > 0 and voxels > max_session_voxels:
        per_session = max_session_voxels * SERVER_BYTES_PER_VOXEL / 1e9
        live = f"; {max_live_sessions} live sessions (server.max_live_sessions) x {per_session:.2f} GB" * (
            max_live_sessions > 0
        )
        raise Invalid(
            f"config: voxel.max_extent {config.voxel.max_extent:g} m / voxel.resolution {config.voxel.resolution:g} m "
            f"is a grid of up to {voxels / 1e6:.1f} M voxels, more than this server's budget of "
            f"{max_session_voxels / 1e6:.1f} M voxels per session (server.max_session_voxels: about "
            f"{SERVER_BYTES_PER_VOXEL} B a voxel in the server, {per_session:.2f} GB a session{live}); "
            "choose a coarser resolution or a smaller max_extent"
        )
    cluster = config.cluster
    fits = cluster.t_max - cluster.t_min + 1
    if cluster.search == "exhaustive" and fits > MAX_EXHAUSTIVE_FITS:
        raise Invalid(
            f"config: cluster.search exhaustive over t_min..t_max = {fits} fits, more than {MAX_EXHAUSTIVE_FITS} "
            "(use search 'fast' or a narrower T range)"
        )
    terms = config.candidates.count * 2 * cluster.t_max
    if terms > MAX_CANDIDATE_TERMS:
        raise Invalid(
            f"config: candidates.count * 2 * cluster.t_max = {terms} projections per plan, more than "
            f"{MAX_CANDIDATE_TERMS} (fewer candidates or a smaller t_max)"
        )


# ---------------------------------------------------------------------- meshes


@dataclass(frozen=True)
class MeshLimits:
    """What a model mesh may cost: loading it and casting rays against it (checked on upload and on use)."""

    max_triangles: int = 2_000_000
    """Triangles after triangulation (an n-gon is n - 2). The Stanford Buddha has 1.1 M."""
    max_vertices: int = 2_000_000
    """Vertices."""
    max_polygon_degree: int = 64
    """Corners of one face (OBJ / OFF polygons; a 4000-corner fan is a ray-casting bomb)."""
    max_triangles_per_vertex: float = 16.0
    """Triangles / vertices (a closed triangle mesh has about 2): many overlapping triangles on few vertices
    make every ray test them all. Checked above ``ratio_from`` triangles."""
    ratio_from: int = 10_000
    """Meshes with fewer triangles than this are cheap whatever their ratio."""

    def __post_init__(self) -> None:
        for name in ("max_triangles", "max_vertices", "max_polygon_degree", "ratio_from"):
            value = getattr(self, name)
            if not isinstance(value, int) or isinstance(value, bool) or value < 3:
                raise ValueError(f"mesh_limits.{name}: must be an integer >= 3, got {value!r}")
        if not isinstance(self.max_triangles_per_vertex, int | float) or not self.max_triangles_per_vertex >= 1:
            raise ValueError(
                f"mesh_limits.max_triangles_per_vertex: must be >= 1, got {self.max_triangles_per_vertex!r}"
            )

    def check_counts(self, what: str, vertices: int, triangles: int, degree: int = 3) -> None:
        """TooLarge (413) naming the first limit ``what`` exceeds."""
        if degree > self.max_polygon_degree:
            raise TooLarge(f"{what}: a face has {degree} corners, over the limit of {self.max_polygon_degree}")
        if vertices > self.max_vertices:
            raise TooLarge(f"{what}: {vertices} vertices, over the limit of {self.max_vertices}")
        if triangles > self.max_triangles:
            raise TooLarge(f"{what}: {triangles} triangles after triangulation, over the limit of {self.max_triangles}")
        if triangles >= self.ratio_from and triangles > self.max_triangles_per_vertex * max(vertices, 1):
            raise TooLarge(
                f"{what}: {triangles} triangles on {vertices} vertices, over the limit of "
                f"{self.max_triangles_per_vertex:g} triangles per vertex (overlapping fans make ray casting explode)"
            )

    def check_file(self, path: Path, what: str) -> None:
        """Pre-scan a file before it is loaded: OBJ / OFF as text, glTF / GLB by their JSON (instancing counted),
        PLY by its header (workbench/sources/mesh_prescan.py); STL is checked by :meth:`check_mesh` after loading.
        ValueError for a file whose header cannot be true."""
        suffix = path.suffix.lower()
        if suffix == ".obj":
            self._scan_obj(path, what)
        elif suffix == ".off":
            self._scan_off(path, what)
        elif suffix in (".glb", ".gltf"):
            vertices, triangles, instances = gltf_counts(gltf_json(path))
            if triangles > self.max_triangles:
                raise TooLarge(
                    f"{what}: its scene holds {triangles} triangles ({instances} mesh instances through its node "
                    f"tree), over the limit of {self.max_triangles}"
                )
            self.check_counts(what, vertices, triangles)
        elif suffix == ".ply":
            vertices, faces, short = ply_counts(path)
            if short is not None:
                raise ValueError(f"truncated PLY: {short}")
            self.check_counts(what, vertices, faces)

    def check_mesh(self, vertices: np.ndarray, faces: np.ndarray, what: str) -> None:
        """The limits on a loaded triangle mesh: ``vertices`` (V, 3), ``faces`` (F, 3)."""
        self.check_counts(what, len(vertices), len(faces))

    def _scan_obj(self, path: Path, what: str) -> None:
        vertices = triangles = degree = 0
        with path.open("rb") as fh:
            for line in fh:
                head = line[:2]
                if head == b"v ":
                    vertices += 1
                elif head == b"f ":
                    corners = len(line.split()) - 1
                    degree = max(degree, corners)
                    triangles += max(corners - 2, 0)
                    if degree > self.max_polygon_degree:
                        break  # refused anyway: stop reading
        self.check_counts(what, vertices, triangles, degree)

    def _scan_off(self, path: Path, what: str) -> None:
        with path.open("rb") as fh:
            rows = (line.split(b"#")[0].split() for line in fh)
            rows = (r for r in rows if r)
            header = next(rows, [])
            if header and header[0].upper().endswith(b"OFF"):
                header = header[1:] or next(rows, [])
            try:
                n_vertices, n_faces = int(header[0]), int(header[1])
            except (IndexError, ValueError):
                return  # not OFF as we know it: the loader says what is wrong
            self.check_counts(what, n_vertices, 0)
            for _ in range(n_vertices):
                next(rows, None)
            triangles = degree = 0
            for _ in range(n_faces):
                row = next(rows, None)
                if row is None:
                    break
                try:
                    corners = int(row[0])
                except ValueError:
                    return
                degree = max(degree, corners)
                triangles += max(corners - 2, 0)
                if degree > self.max_polygon_degree:
                    break
        self.check_counts(what, n_vertices, triangles, degree)
