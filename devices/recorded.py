"""Recorded view sets: real views with their poses, read from disk, and a cell whose candidates are those views.

A lab records its object once (densely, from known poses) and the planners then choose among the recorded
views, the way NBV methods are checked on real data (BigBIRD- and YCB-style capture rigs). Two readers:

- :func:`read_stanford`: the Stanford 3D Scanning Repository's range scans (an ASCII PLY per scan with an
  ``obj_info`` header, a vertex list and a ``range_grid`` that maps each cell of the organised scan to zero or one
  vertex; a ``.conf`` of ``bmesh FILE tx ty tz qi qj qk qw`` lines). The conf's quaternion is applied
  **inverted**: ``p_ref = R(q)^-1 p_scan + t`` (taken as written only the identity and the half-turn scans land on
  the reference mesh). No scanner pose is given; :func:`scanner_direction` derives the viewing direction of each
  scan from its range grid (below).
- :func:`read_view_folder`: our own plain folder format (``views.json`` + one depth image or point cloud per view,
  documented in docs/real-data.md); :func:`write_view_folder` writes it (a simulated session exported to it reads
  back with the same coverage per view).

Placement: a set is put on the plate as our meshes are (``devices.mesh.place_on_plate`` without scaling: real
metres stay metres): y-up turned to z-up when the set says so, centred on the turntable axis, its lowest point (of
the reference mesh when there is one, else of all registered views) on the plate top (z = 0).

A view becomes a :class:`planner.types.DepthFrame` by z-buffering its points into a virtual pinhole camera
(``RecordedSet.intrinsics``) at its pose: the planner's frames are images. The depth of each kept point is exact;
its lateral position moves to its pixel's centre (at most half a pixel: 0.3 mm with the Stanford set's default
camera).
"""

from __future__ import annotations

import json
import math
from collections.abc import Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
import trimesh
from numpy.typing import NDArray
from scipy.spatial.transform import Rotation

from devices.angles import wrap_angle
from devices.cell import Cell, Motion, rz
from devices.cellreach import SphereReach
from devices.config import CellConfig
from devices.move_capture import OnFrame
from devices.protocols import CaptureError, UnreachableError
from devices.sim import SimulatedArm, SimulatedTurntable
from planner.types import DepthFrame, Intrinsics, Pose

__all__ = [
    "RecordedCell",
    "RecordedSet",
    "RecordedView",
    "read_recorded",
    "read_stanford",
    "read_view_folder",
    "scanner_direction",
    "write_view_folder",
]

MAX_VIEWS = 500
"""A recorded set may hold at most this many views."""
STANFORD_DISTANCE = 0.40
"""Metres from a Stanford scan's points' centre to the virtual camera placed on its derived viewing direction."""
STANFORD_INTRINSICS = Intrinsics(width=640, height=480, fx=700.0, fy=700.0, cx=319.5, cy=239.5)
"""The virtual camera the Stanford scans are imaged with: 0.57 mm pixels at 0.40 m, about the scans' own 0.5 mm
spacing, and 0.37 x 0.27 m in view there (the bunny is 0.16 m)."""
POSE_MATCH = 1e-6
"""Metres and radians: a pose this close to a recorded view's is that view."""
Y_TO_Z_UP = Pose(np.array([[1.0, 0.0, 0.0], [0.0, 0.0, -1.0], [0.0, 1.0, 0.0]]), np.zeros(3))
"""+90 degrees about x: a y-up object's up axis becomes z (as ``devices.mesh.place_on_plate`` does)."""


@dataclass(frozen=True, eq=False)
class RecordedView:
    """One recorded view.

    name: the view's name (its file stem). points_sensor: (N, 3) float64 the view's points in its sensor frame
    (OpenCV axes: +z forward). T_world_sensor: the recorded pose in the table frame (with whatever error it has).
    depth: (H, W) float32 the view's own depth image when it was recorded as one (else None: imaged from points).
    """

    name: str
    points_sensor: NDArray[np.float64]
    T_world_sensor: Pose
    depth: NDArray[np.float32] | None = None

    def __post_init__(self) -> None:
        p = np.asarray(self.points_sensor, dtype=np.float64)
        if p.ndim != 2 or p.shape[1] != 3:
            raise ValueError(f"view {self.name!r}: points_sensor must be (N, 3), got shape {p.shape}")
        if not np.all(np.isfinite(p)):
            raise ValueError(f"view {self.name!r}: points_sensor has non-finite values")
        object.__setattr__(self, "points_sensor", p)

    @property
    def points_world(self) -> NDArray[np.float64]:
        """(N, 3) the view's points registered by its recorded pose, table frame."""
        return self.T_world_sensor.apply(self.points_sensor)


@dataclass(frozen=True, eq=False)
class RecordedSet:
    """A set of recorded views of one object, placed on the plate (table frame).

    name: the set's name. views: the views, in the order recorded. intrinsics: the (virtual) camera the views are
    imaged with. reference: the reference mesh in the table frame, None when there is none (the set is then
    scored against the union of its registered views). plate_angles: (V,) radians, the plate angle each view
    implies (the plate turns the view's azimuth onto the arm's). source: how the set was read, for reports.
    """

    name: str
    views: tuple[RecordedView, ...]
    intrinsics: Intrinsics
    reference: trimesh.Trimesh | None = None
    source: str = ""
    plate_angles: NDArray[np.float64] = field(default_factory=lambda: np.zeros(0))

    def __post_init__(self) -> None:
        if not self.views:
            raise ValueError(f"recorded set {self.name!r}: no views")
        if len(self.views) > MAX_VIEWS:
            raise ValueError(f"recorded set {self.name!r}: {len(self.views)} views, more than {MAX_VIEWS}")
        names = [v.name for v in self.views]
        if len(set(names)) != len(names):
            raise ValueError(f"recorded set {self.name!r}: view names repeat")
        if len(self.plate_angles) != len(self.views):
            arm_azimuth = math.atan2(CellConfig().arm_base[1], CellConfig().arm_base[0])
            angles = [
                wrap_angle(arm_azimuth - math.atan2(v.T_world_sensor.translation[1], v.T_world_sensor.translation[0]))
                for v in self.views
            ]
            object.__setattr__(self, "plate_angles", np.array(angles, dtype=np.float64))

    @property
    def poses(self) -> list[Pose]:
        """``T_world_sensor`` of every view, in order: the candidate views of a :class:`RecordedCell`."""
        return [v.T_world_sensor for v in self.views]

    def frame(self, index: int, T_world_camera: Pose | None = None) -> DepthFrame:
        """View ``index`` as a DepthFrame with its recorded pose (or ``T_world_camera``: e.g. a perturbed one)."""
        view = self.views[index]
        pose = view.T_world_sensor if T_world_camera is None else T_world_camera
        if view.depth is not None:
            return DepthFrame(view.depth, pose, self.intrinsics)
        return DepthFrame(image_points(view.points_sensor, self.intrinsics), pose, self.intrinsics)

    def union_world(self) -> NDArray[np.float64]:
        """(N, 3) every view's points registered by its recorded pose (the ground truth without a reference)."""
        return np.concatenate([v.points_world for v in self.views])

    def index_of(self, T_world_camera: Pose) -> int | None:
        """The view whose recorded pose is ``T_world_camera`` (within :data:`POSE_MATCH`), None if none is."""
        for i, view in enumerate(self.views):
            if pose_distance(view.T_world_sensor, T_world_camera) <= POSE_MATCH:
                return i
        return None


def pose_distance(a: Pose, b: Pose) -> float:
    """The larger of the translation distance (m) and the rotation angle (rad) between ``a`` and ``b``."""
    angle = float(np.linalg.norm(Rotation.from_matrix(a.rotation.T @ b.rotation).as_rotvec()))
    return max(float(np.linalg.norm(a.translation - b.translation)), angle)


def image_points(points_sensor: NDArray[np.float64], intrinsics: Intrinsics) -> NDArray[np.float32]:
    """(H, W) float32 z-buffer of ``points_sensor`` (N, 3) (the nearest point per pixel, 0 where none)."""
    return DepthFrame.from_points(points_sensor, Pose.identity(), intrinsics).depth


# ---------------------------------------------------------------------- the Stanford range-scan format


@dataclass(frozen=True, eq=False)
class RangeScan:
    """One Stanford range scan as read: points (N, 3) in the scan's frame, the grid (rows, cols) of vertex indices
    (-1: no return), and the ``obj_info`` lines."""

    points: NDArray[np.float64]
    grid: NDArray[np.int64]
    info: dict[str, str]


def read_range_ply(path: str | Path) -> RangeScan:
    """Read an ASCII PLY range image (``obj_info num_cols`` / ``num_rows``, vertices x y z, ``range_grid`` lists of
    0 or 1 vertex index). ValueError naming the file for anything else."""
    p = Path(path)
    try:
        text = p.read_bytes().decode("ascii")
    except (OSError, UnicodeDecodeError) as exc:
        raise ValueError(f"{p.name}: not readable as an ASCII PLY ({exc})") from None
    if not text.startswith("ply") or "end_header" not in text:
        raise ValueError(f"{p.name}: not a PLY file (no 'ply' magic / 'end_header')")
    head, body = text.split("end_header", 1)
    info: dict[str, str] = {}
    counts: dict[str, int] = {}
    for line in head.splitlines():
        parts = line.split()
        if parts[:1] == ["format"] and parts[1:2] != ["ascii"]:
            raise ValueError(f"{p.name}: only ASCII range PLYs are read, got format {parts[1:2]}")
        if parts[:1] == ["obj_info"] and len(parts) >= 3:
            info[parts[1]] = parts[2]
        if parts[:1] == ["element"] and len(parts) == 3:
            counts[parts[1]] = int(parts[2])
    try:
        cols, rows = int(info["num_cols"]), int(info["num_rows"])
    except (KeyError, ValueError):
        raise ValueError(f"{p.name}: obj_info num_cols / num_rows missing: not a range image") from None
    n_vertex, n_grid = counts.get("vertex", 0), counts.get("range_grid", -1)
    if n_grid != rows * cols:
        raise ValueError(f"{p.name}: range_grid has {n_grid} cells, expected num_rows x num_cols = {rows * cols}")
    lines = body.strip("\r\n").splitlines()
    if len(lines) < n_vertex + n_grid:
        raise ValueError(f"{p.name}: truncated ({len(lines)} data lines, expected {n_vertex + n_grid})")
    try:
        points = np.array(" ".join(lines[:n_vertex]).split(), dtype=np.float64).reshape(n_vertex, 3)
    except ValueError:
        raise ValueError(f"{p.name}: vertex lines must hold three numbers each") from None
    if not np.all(np.isfinite(points)):
        raise ValueError(f"{p.name}: non-finite vertex coordinates")
    grid = np.full(n_grid, -1, dtype=np.int64)
    for i, line in enumerate(lines[n_vertex : n_vertex + n_grid]):
        if line[:1] != "0":
            fields = line.split()
            if len(fields) != 2 or fields[0] != "1":
                raise ValueError(f"{p.name}: range_grid cell {i}: expected '0' or '1 INDEX', got {line!r}")
            grid[i] = int(fields[1])
    if grid.max(initial=-1) >= n_vertex:
        raise ValueError(f"{p.name}: range_grid refers to vertex {int(grid.max())} of {n_vertex}")
    return RangeScan(points, grid.reshape(rows, cols), info)


def scanner_direction(scan: RangeScan, centre: NDArray[np.float64] | None = None) -> NDArray[np.float64]:
    """(3,) unit vector in the scan's frame from the object towards the scanner.

    An organised range image's rows and columns are the scanner's lateral coordinates and its range runs across
    them: a point's position along the lateral axes follows from its (column, row) cell, its position along the
    viewing axis does not (that is the object's shape). So the points are regressed on (column, row, 1) by least
    squares and the viewing axis is the direction of the largest residual variance (the principal axis of what the
    grid cell does not explain). Its sign: with the object's ``centre`` (3,) in the scan's frame, the scanner is on
    the side of the centre its points are (a scan sees the near side of the object); without it, the surface
    normals of neighbouring cells (cross products of the column and row steps) face the scanner on a visible
    surface, so their sum points to it, which holds for a grid laid out as the scanner's own right-handed image
    axes (the Stanford scans: both rules agree on all ten). ValueError for a scan of fewer than 4 returns.
    """
    rows, cols = np.nonzero(scan.grid >= 0)
    if rows.size < 4:
        raise ValueError("range scan: fewer than 4 returns, no viewing direction")
    pts = scan.points[scan.grid[rows, cols]]
    design = np.column_stack([cols, rows, np.ones(rows.size)]).astype(np.float64)
    coef, *_ = np.linalg.lstsq(design, pts, rcond=None)
    residual = pts - design @ coef
    _, vectors = np.linalg.eigh(residual.T @ residual)
    axis = vectors[:, -1]
    if centre is not None:
        return axis if float((pts.mean(axis=0) - np.asarray(centre, dtype=np.float64)) @ axis) >= 0 else -axis
    grid_points = np.full((*scan.grid.shape, 3), np.nan)
    grid_points[rows, cols] = pts
    d_col = grid_points[:-1, 1:] - grid_points[:-1, :-1]
    d_row = grid_points[1:, :-1] - grid_points[:-1, :-1]
    normals = np.cross(d_col, d_row).reshape(-1, 3)
    normals = normals[np.all(np.isfinite(normals), axis=1)]
    unit = normals / np.linalg.norm(normals, axis=1, keepdims=True).clip(1e-12)
    if len(unit) and float(unit.sum(axis=0) @ axis) < 0:
        axis = -axis
    return axis


def trim_edges(scan: RangeScan, cells: int) -> RangeScan:
    """``scan`` without the returns within ``cells`` grid cells (chessboard distance) of a cell without one: the
    rims of what the scanner saw, where it measures at grazing angles and mixes foreground and background."""
    if cells <= 0:
        return scan
    from scipy import ndimage

    has = scan.grid >= 0
    to_hole = np.asarray(ndimage.distance_transform_cdt(np.pad(has, 1), metric="chessboard"))
    keep = has & (to_hole[1:-1, 1:-1] > cells)
    index = np.full(len(scan.points), -1, dtype=np.int64)
    kept = scan.grid[keep]
    index[kept] = np.arange(len(kept))
    grid = np.where(keep, index[np.where(has, scan.grid, 0)], -1)
    return RangeScan(scan.points[kept], grid, scan.info)


def read_conf(path: str | Path) -> dict[str, Pose]:
    """``{file name: T_ref_scan}`` of a Stanford ``.conf`` (``bmesh FILE tx ty tz qi qj qk qw``, the quaternion
    scalar-last and applied inverted: ``p_ref = R(q)^-1 p_scan + t``). ValueError naming the line otherwise."""
    p = Path(path)
    out: dict[str, Pose] = {}
    for number, line in enumerate(p.read_text(encoding="ascii", errors="replace").splitlines(), start=1):
        parts = line.split()
        if parts[:1] != ["bmesh"]:
            continue
        if len(parts) != 9:
            raise ValueError(f"{p.name}:{number}: expected 'bmesh FILE tx ty tz qi qj qk qw', got {line!r}")
        try:
            values = np.array([float(v) for v in parts[2:]])
        except ValueError:
            raise ValueError(f"{p.name}:{number}: non-numeric pose in {line!r}") from None
        q = values[3:]
        if not (np.all(np.isfinite(values)) and abs(np.linalg.norm(q) - 1.0) < 1e-3):
            raise ValueError(f"{p.name}:{number}: the quaternion must be finite and of unit length")
        rotation = Rotation.from_quat(q / np.linalg.norm(q)).inv().as_matrix()
        out[parts[1]] = Pose(rotation, values[:3])
    if not out:
        raise ValueError(f"{p.name}: no 'bmesh' lines")
    return out


def _placement(points_ref: NDArray[np.float64], up: str) -> Pose:
    """``T_table_ref``: turn ``up`` to z, centre on the plate axis, lowest point on the plate top."""
    turn = Y_TO_Z_UP if up == "y" else Pose.identity()
    p = turn.apply(points_ref)
    lower, upper = p.min(axis=0), p.max(axis=0)
    shift = -np.array([0.5 * (lower[0] + upper[0]), 0.5 * (lower[1] + upper[1]), lower[2]])
    return Pose(np.eye(3), shift) @ turn


def _sensor_pose(direction: NDArray[np.float64], points: NDArray[np.float64], distance: float) -> Pose:
    """``T_scan_sensor``: a camera ``distance`` from the points' centre on ``direction``, looking back along it."""
    centre = 0.5 * (points.min(axis=0) + points.max(axis=0))
    z = -direction
    helper = np.array([0.0, 1.0, 0.0]) if abs(z[1]) < 0.9 else np.array([1.0, 0.0, 0.0])
    x = np.cross(helper, z)
    x /= np.linalg.norm(x)
    y = np.cross(z, x)
    return Pose(np.column_stack([x, y, z]), centre - distance * z)


def read_stanford(
    folder: str | Path,
    *,
    conf: str | Path | None = None,
    reference: str | Path | None = None,
    up: str = "y",
    distance: float = STANFORD_DISTANCE,
    intrinsics: Intrinsics = STANFORD_INTRINSICS,
    edge_trim: int = 0,
) -> RecordedSet:
    """A folder of Stanford range scans as a :class:`RecordedSet` (module docstring).

    conf: the ``.conf`` (default: the folder's only ``*.conf``). reference: a mesh in the conf's reference frame
    (default: ``*_zipper.ply`` in the folder when there is one; pass "" for none). up: the data's up axis.
    Each scan's virtual sensor stands ``distance`` from its points' centre on :func:`scanner_direction`, looking
    back along it. edge_trim: drop the returns within this many grid cells of a cell without one
    (:func:`trim_edges`: a scanner's worst points are at the edges of what it saw). ValueError naming the file for a
    missing or malformed one.
    """
    if not (isinstance(edge_trim, int) and edge_trim >= 0):
        raise ValueError(f"edge_trim: must be an integer >= 0, got {edge_trim!r}")
    root = Path(folder)
    if not root.is_dir():
        raise ValueError(f"recorded set {str(folder)!r}: not a folder")
    if up not in ("y", "z"):
        raise ValueError(f"up: must be 'y' or 'z', got {up!r}")
    if conf is None:
        confs = sorted(root.glob("*.conf"))
        if len(confs) != 1:
            raise ValueError(f"{root.name}: expected one .conf file, found {len(confs)}")
        conf = confs[0]
    poses = read_conf(conf)
    scans: list[tuple[str, RangeScan, Pose]] = []
    for file_name, T_ref_scan in poses.items():
        path = root / file_name
        if not path.is_file():
            raise ValueError(f"{Path(conf).name}: scan {file_name!r} not found in {root.name}")
        scans.append((Path(file_name).stem, trim_edges(read_range_ply(path), edge_trim), T_ref_scan))
    mesh: trimesh.Trimesh | None = None
    if reference is None:
        zippers = sorted(root.glob("*_zipper.ply"))
        reference = zippers[0] if zippers else ""
    if reference != "":
        loaded = trimesh.load(str(reference), force="mesh", process=False)
        if not isinstance(loaded, trimesh.Trimesh) or len(loaded.faces) == 0:
            raise ValueError(f"{Path(reference).name}: not a triangle mesh")
        mesh = loaded
    ref_points = (
        np.asarray(mesh.vertices, dtype=np.float64)
        if mesh is not None
        else np.concatenate([T.apply(s.points) for _, s, T in scans])
    )
    T_table_ref = _placement(ref_points, up)
    centre_ref = 0.5 * (ref_points.min(axis=0) + ref_points.max(axis=0))
    views = []
    for name, scan, T_ref_scan in scans:
        direction = scanner_direction(scan, T_ref_scan.inverse().apply(centre_ref[None])[0])
        T_scan_sensor = _sensor_pose(direction, scan.points, distance)
        views.append(
            RecordedView(name, T_scan_sensor.inverse().apply(scan.points), T_table_ref @ T_ref_scan @ T_scan_sensor)
        )
    if mesh is not None:
        mesh = trimesh.Trimesh(T_table_ref.apply(np.asarray(mesh.vertices)), np.asarray(mesh.faces), process=False)
    return RecordedSet(root.name, tuple(views), intrinsics, mesh, source=f"stanford:{root}")


# ---------------------------------------------------------------------- our folder format

MANIFEST = "views.json"
FORMAT = "nbv-views"


def _matrix_pose(value: Any, where: str) -> Pose:
    try:
        T = np.asarray(value, dtype=np.float64)
    except (TypeError, ValueError):
        raise ValueError(f"{where}: T_world_camera must be a 4x4 matrix of numbers") from None
    if T.shape != (4, 4) or not np.all(np.isfinite(T)) or not np.allclose(T[3], (0, 0, 0, 1)):
        raise ValueError(f"{where}: T_world_camera must be a finite 4x4 matrix with last row 0 0 0 1")
    try:
        return Pose.from_matrix(T)
    except ValueError as exc:
        raise ValueError(f"{where}: T_world_camera: {exc}") from None


def _inside(root: Path, name: Any, where: str) -> Path:
    if not isinstance(name, str) or not name:
        raise ValueError(f"{where}: needs a file name")
    path = root / name
    try:
        ok = path.is_file() and path.resolve().is_relative_to(root.resolve())
    except OSError:
        ok = False
    if not ok:
        raise ValueError(f"{where}: {name!r} is not a file inside {root.name}")
    return path


def _read_depth(path: Path, scale: float, k: Intrinsics, where: str) -> NDArray[np.float32]:
    if path.suffix == ".npy":
        depth = np.load(path, allow_pickle=False).astype(np.float32)
    elif path.suffix == ".png":
        from PIL import Image

        with Image.open(path) as image:
            depth = (np.asarray(image).astype(np.float64) * scale).astype(np.float32)
    else:
        raise ValueError(f"{where}: depth images are .npy (float metres) or 16-bit .png (x depth_scale)")
    if depth.shape != (k.height, k.width):
        raise ValueError(f"{where}: depth image {depth.shape} differs from the intrinsics ({k.height}, {k.width})")
    if not np.all(np.isfinite(depth)) or np.any(depth < 0):
        raise ValueError(f"{where}: depth must be finite and >= 0 (0: no return)")
    return depth


def read_view_folder(folder: str | Path) -> RecordedSet:
    """A folder in our own format (``views.json`` + per view a depth image or a point cloud; docs/real-data.md) as a
    :class:`RecordedSet`. ValueError naming the file and field for anything malformed."""
    from devices.ply import read_ply
    from devices.replay import _intrinsics

    root = Path(folder)
    manifest_path = root / MANIFEST
    if not manifest_path.is_file():
        raise ValueError(f"recorded set {str(folder)!r}: no {MANIFEST}")
    try:
        manifest = json.loads(manifest_path.read_text(encoding="utf-8"))
    except (OSError, UnicodeDecodeError, json.JSONDecodeError) as exc:
        raise ValueError(f"{MANIFEST}: not readable JSON ({exc})") from None
    if not isinstance(manifest, dict) or manifest.get("format") != FORMAT:
        raise ValueError(f'{MANIFEST}: needs "format": "{FORMAT}"')
    k = _intrinsics(manifest.get("intrinsics"), f"{MANIFEST}: intrinsics")
    scale = manifest.get("depth_scale", 0.001)
    if not (isinstance(scale, int | float) and math.isfinite(scale) and scale > 0):
        raise ValueError(f"{MANIFEST}: depth_scale must be a number > 0 (metres per unit of a .png)")
    up = manifest.get("up", "z")
    if up not in ("y", "z"):
        raise ValueError(f"{MANIFEST}: up must be 'y' or 'z', got {up!r}")
    entries = manifest.get("views")
    if not isinstance(entries, list) or not entries:
        raise ValueError(f"{MANIFEST}: needs a non-empty list 'views'")
    views = []
    for i, entry in enumerate(entries):
        where = f"{MANIFEST}: views[{i}]"
        if not isinstance(entry, dict):
            raise ValueError(f"{where}: must be an object")
        name = entry.get("name", f"view{i:03d}")
        pose = _matrix_pose(entry.get("T_world_camera"), where)
        if ("depth" in entry) == ("points" in entry):
            raise ValueError(f"{where}: give exactly one of 'depth' (an image) and 'points' (a .ply cloud)")
        if "depth" in entry:
            depth = _read_depth(_inside(root, entry["depth"], where), float(scale), k, where)
            points = DepthFrame(depth, Pose.identity(), k).points_camera
            views.append(RecordedView(str(name), points, pose, depth))
        else:
            points = read_ply(_inside(root, entry["points"], where))
            frame = entry.get("points_frame", "camera")
            if frame not in ("camera", "world"):
                raise ValueError(f"{where}: points_frame must be 'camera' or 'world', got {frame!r}")
            if frame == "world":
                points = pose.inverse().apply(points)
            views.append(RecordedView(str(name), points, pose))
    mesh = None
    if manifest.get("reference"):
        mesh = trimesh.load(str(_inside(root, manifest["reference"], f"{MANIFEST}: reference")), force="mesh")
        if not isinstance(mesh, trimesh.Trimesh) or len(mesh.faces) == 0:
            raise ValueError(f"{MANIFEST}: reference is not a triangle mesh")
    recorded = RecordedSet(str(manifest.get("name", root.name)), tuple(views), k, mesh, source=f"folder:{root}")
    if up == "y" or manifest.get("place_on_plate", False):
        recorded = placed(recorded, up)
    return recorded


def placed(recorded: RecordedSet, up: str) -> RecordedSet:
    """``recorded`` moved onto the plate (module docstring): poses and reference mesh transformed together."""
    ref = recorded.reference
    T = _placement(np.asarray(ref.vertices) if ref is not None else recorded.union_world(), up)
    views = tuple(RecordedView(v.name, v.points_sensor, T @ v.T_world_sensor, v.depth) for v in recorded.views)
    mesh = None if ref is None else trimesh.Trimesh(T.apply(np.asarray(ref.vertices)), ref.faces, process=False)
    return RecordedSet(recorded.name, views, recorded.intrinsics, mesh, recorded.source)


def write_view_folder(
    folder: str | Path,
    frames: Sequence[DepthFrame],
    *,
    names: Sequence[str] | None = None,
    reference: trimesh.Trimesh | None = None,
    name: str = "recorded",
) -> Path:
    """Write ``frames`` (one intrinsics) in our folder format: ``views.json`` and a float32 ``.npy`` depth image per
    view (``reference``: a mesh in the table frame, written as ``reference.ply``). Returns the manifest's path."""
    if not frames:
        raise ValueError("frames: nothing to write")
    k = frames[0].intrinsics
    if any(f.intrinsics != k for f in frames):
        raise ValueError("frames: all views of a set share one intrinsics")
    names = list(names) if names is not None else [f"view{i:03d}" for i in range(len(frames))]
    root = Path(folder)
    root.mkdir(parents=True, exist_ok=True)
    entries = []
    for view_name, frame in zip(names, frames, strict=True):
        np.save(root / f"{view_name}.npy", frame.depth.astype(np.float32))
        entries.append(
            {"name": view_name, "depth": f"{view_name}.npy", "T_world_camera": frame.T_world_camera.matrix.tolist()}
        )
    manifest: dict[str, Any] = {
        "format": FORMAT,
        "name": name,
        "intrinsics": {"width": k.width, "height": k.height, "fx": k.fx, "fy": k.fy, "cx": k.cx, "cy": k.cy},
        "up": "z",
        "views": entries,
    }
    if reference is not None:
        reference.export(str(root / "reference.ply"))
        manifest["reference"] = "reference.ply"
    path = root / MANIFEST
    path.write_text(json.dumps(manifest, indent=1), encoding="utf-8")
    return path


def read_recorded(path: str | Path, reference: str | Path | None = None, edge_trim: int = 0) -> RecordedSet:
    """The recorded set at ``path``: our folder format when it holds ``views.json``, else Stanford range scans (a
    ``.conf``). ``reference``: a reference mesh in the set's frame for the Stanford reader (its own by default)."""
    root = Path(path)
    if (root / MANIFEST).is_file():
        return read_view_folder(root)
    if root.is_dir() and any(root.glob("*.conf")):
        return read_stanford(root, reference=reference, edge_trim=edge_trim)
    raise ValueError(f"recorded set {str(path)!r}: neither {MANIFEST} nor a Stanford .conf found")


# ---------------------------------------------------------------------- the cell


class RecordedCamera:
    """Returns the recorded view the cell stands at (CaptureError between views)."""

    def __init__(self, recorded: RecordedSet, pose_source: Any) -> None:
        self.recorded = recorded
        self.pose_source = pose_source
        self.captures = 0
        self.fail_next: Exception | None = None

    @property
    def intrinsics(self) -> Intrinsics:
        return self.recorded.intrinsics

    def capture(self) -> DepthFrame:
        if self.fail_next is not None:
            exc, self.fail_next = self.fail_next, None
            raise exc
        index = self.recorded.index_of(self.pose_source())
        if index is None:
            raise CaptureError("recorded set: the camera is at no recorded view")
        self.captures += 1
        return self.recorded.frame(index)


class RecordedCell(Cell):
    """A cell whose candidate views are a recorded set's views (:meth:`candidate_poses`): a move goes to a recorded
    view only (UnreachableError otherwise), turning the plate to the angle the view implies; a capture returns that
    view's recorded data with its recorded pose. Moves are not timed (the views were taken already)."""

    def __init__(self, recorded: RecordedSet, config: CellConfig | None = None) -> None:
        from dataclasses import replace

        # no arm to plan for: the views were taken already (the reach sphere only keeps the cell's state)
        config = replace(config if config is not None else CellConfig(), kinematics="reach_sphere")
        arm = SimulatedArm()
        turntable = SimulatedTurntable()
        camera = RecordedCamera(recorded, pose_source=lambda: self.pose)
        super().__init__(camera, arm, turntable, config, reach=SphereReach(config, arm, turntable))
        self.recorded = recorded
        self._at: int | None = None

    @property
    def reach_of_config(self) -> bool:
        """Reachability is the recorded set's, which a worker's planning cell of the same config does not know."""
        return False

    def candidate_poses(self) -> list[Pose]:
        return self.recorded.poses

    def initial_pose(self) -> Pose:
        return self.recorded.views[0].T_world_sensor

    def is_reachable(self, T_table_camera: Pose) -> bool:
        return self.recorded.index_of(T_table_camera) is not None

    def move_costs(self, candidates: Sequence[Any], eligible: NDArray[np.bool_]) -> NDArray[np.float64]:
        """Zero for every eligible view: a recorded set has no move times."""
        return np.where(np.asarray(eligible, dtype=bool), 0.0, math.inf)

    def move_times(
        self, candidates: Sequence[Any], indices: Sequence[int], *, exact: bool = False
    ) -> NDArray[np.float64]:
        """The camera's straight travel between the views at 0.25 m/s (a recorded set has no arm to time)."""
        points = [self.pose.translation] + [candidates[i].T_world_camera.translation for i in indices]
        p = np.asarray(points)
        return np.linalg.norm(p[:, None] - p[None], axis=2) / 0.25

    def plan_motion(self, T_table_camera: Pose, plate_angle: float | None = None, then: Sequence[Pose] = ()) -> Motion:
        index = self.recorded.index_of(T_table_camera)
        if index is None:
            raise UnreachableError("unreachable: not a recorded view of this set")
        angle = float(self.recorded.plate_angles[index]) if plate_angle is None else plate_angle
        return Motion(angle, rz(angle) @ T_table_camera, timed=False)

    def move_to(
        self,
        T_table_camera: Pose,
        plate_angle: float | None = None,
        then: Sequence[Pose] = (),
        motion: Motion | None = None,
        capture_hz: float = 0.0,
        on_frame: OnFrame | None = None,
    ) -> Motion:
        """Turn the plate and put the camera at the recorded view (not timed: no frames during the move, whatever
        ``capture_hz``)."""
        done = motion if motion is not None else self.plan_motion(T_table_camera, plate_angle, then)
        self.turntable.rotate_to(done.angle)
        self.arm.move_to(done.T_base_camera)
        self.last_motion = done
        return done

    def capture(self) -> DepthFrame:
        return self.camera.capture()
