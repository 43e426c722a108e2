"""Loading an object mesh and placing it on the turntable plate.

Every object, loaded or built in, is placed the same way (:func:`place_on_plate`):
z-up, scaled so its largest bounding-box extent is ``size`` metres, the centre of
its bounding box in x and y on the turntable axis, its lowest point on the plate
top (z = 0). Meshes need not be watertight (the Stanford bunny and buddha are not).
"""

from __future__ import annotations

import contextlib
from pathlib import Path
from typing import Literal

import numpy as np
import trimesh
from numpy.typing import NDArray

UpAxis = Literal["y", "z"]

SUPPORTED_SUFFIXES = (".ply", ".obj", ".stl", ".off", ".glb", ".gltf")
"""File types :func:`load_mesh` reads."""


class MeshError(ValueError):
    """A mesh cannot be used: the message is one line naming the file and what is wrong."""


def _one_line(text: str, limit: int = 160) -> str:
    text = " ".join(str(text).split())
    return text if len(text) <= limit else text[: limit - 3] + "..."


def _check_options(up: object, size: object) -> None:
    if up not in ("y", "z"):
        raise MeshError(f"up: must be 'y' or 'z', got {up!r}")
    if not isinstance(size, int | float) or isinstance(size, bool) or not np.isfinite(size) or size <= 0:
        raise MeshError(f"size: must be a finite number > 0 (metres), got {size!r}")


def load_mesh(path: str | Path, up: UpAxis = "y", size: float = 0.2) -> trimesh.Trimesh:
    """Read a PLY/OBJ/STL/OFF/GLB/glTF triangle mesh and place it on the plate.

    path: the mesh file. A GLB/glTF scene is flattened (transforms applied) and
    its meshes concatenated. up: the file's up axis ('y' is rotated +90 degrees
    about x so that +y becomes +z). size: largest extent after scaling, metres.
    Returns a new mesh, vertices (V, 3) float64 in the table frame.
    Raises :class:`MeshError` (a ``ValueError``) with one line for a missing or
    unreadable file, an unsupported type, a file without triangles, non-finite
    vertices, a degenerate mesh, or bad ``up``/``size``.
    """
    _check_options(up, size)
    p = Path(path)
    if not p.exists():
        raise MeshError(f"{p}: no such file")
    if not p.is_file():
        raise MeshError(f"{p}: not a file")
    suffix = p.suffix.lower()
    if suffix not in SUPPORTED_SUFFIXES:
        kinds = ", ".join(s[1:] for s in SUPPORTED_SUFFIXES)
        raise MeshError(f"{p}: unsupported file type {suffix or '(none)'!r} (supported: {kinds})")
    try:
        loaded = trimesh.load(str(p), file_type=suffix[1:], process=False)
    except MemoryError:  # not the file's fault as such: the caller's memory limit says what it costs
        raise
    except Exception as exc:  # trimesh raises many types for corrupt files
        raise MeshError(
            f"{p}: cannot read as {suffix[1:].upper()} ({_one_line(f'{type(exc).__name__}: {exc}')})"
        ) from None
    mesh = _as_mesh(loaded, p)
    return place_on_plate(mesh, up=up, size=size, name=str(p))


def _as_mesh(loaded: object, p: Path) -> trimesh.Trimesh:
    """The triangle mesh in what trimesh returned, or MeshError saying what it was instead."""
    if isinstance(loaded, trimesh.Scene):
        geoms = loaded.dump()
        meshes = [g for g in geoms if isinstance(g, trimesh.Trimesh) and len(g.faces) > 0]
        if not meshes:
            if any(isinstance(g, trimesh.PointCloud) for g in geoms):
                raise MeshError(f"{p}: contains a point cloud, not a triangle mesh")
            if geoms and not any(isinstance(g, trimesh.Trimesh) for g in geoms):
                kinds = sorted({type(g).__name__ for g in geoms})
                raise MeshError(f"{p}: contains {', '.join(kinds)}, not a triangle mesh")
            raise MeshError(f"{p}: empty mesh (no faces)")
        loaded = meshes[0] if len(meshes) == 1 else trimesh.util.concatenate(meshes)
    if isinstance(loaded, trimesh.PointCloud):
        if "tristrips" in _ply_elements(p):
            raise MeshError(
                f"{p}: its faces are triangle strips (PLY element 'tristrips'), which cannot be read; "
                "save it with a 'face' element (triangles) instead"
            )
        raise MeshError(f"{p}: contains a point cloud ({len(loaded.vertices)} points), not a triangle mesh")
    if not isinstance(loaded, trimesh.Trimesh):
        raise MeshError(f"{p}: contains a {type(loaded).__name__}, not a triangle mesh")
    if len(loaded.faces) == 0:
        raise MeshError(f"{p}: empty mesh (no faces)")
    return loaded


def _ply_elements(p: Path) -> set[str]:
    """The element names of a PLY file's header (empty for another format or an unreadable header)."""
    names: set[str] = set()
    if p.suffix.lower() != ".ply":
        return names
    with contextlib.suppress(OSError), p.open("rb") as fh:
        for _ in range(1000):
            words = fh.readline().split()
            if not words or words[0] == b"end_header":
                break
            if words[0] == b"element" and len(words) > 1:
                names.add(words[1].decode("latin-1"))
    return names


def place_on_plate(mesh: trimesh.Trimesh, up: UpAxis = "z", size: float = 0.2, name: str = "mesh") -> trimesh.Trimesh:
    """A copy of ``mesh`` converted to z-up, scaled and centred on the plate (see the module docstring).

    Only vertices used by a face count for the bounding box. ``name`` prefixes error messages.
    Raises MeshError for no faces, non-finite vertices or a zero extent.
    """
    _check_options(up, size)
    vertices = np.asarray(mesh.vertices, dtype=np.float64)
    faces = np.asarray(mesh.faces, dtype=np.int64)
    if faces.ndim != 2 or faces.shape[1] != 3 or len(faces) == 0:
        raise MeshError(f"{name}: empty mesh (no faces)")
    if faces.min() < 0 or faces.max() >= len(vertices):
        raise MeshError(f"{name}: face indices out of range (0..{len(vertices) - 1})")
    used, faces = np.unique(faces, return_inverse=True)
    faces = faces.reshape(-1, 3)
    vertices = vertices[used]
    if not np.all(np.isfinite(vertices)):
        bad = int(np.count_nonzero(~np.all(np.isfinite(vertices), axis=1)))
        raise MeshError(f"{name}: {bad} vertices with non-finite coordinates (NaN or inf)")
    if up == "y":
        # +90 degrees about x: (x, y, z) -> (x, -z, y), so +y becomes +z.
        vertices = np.column_stack([vertices[:, 0], -vertices[:, 2], vertices[:, 1]])
    lower, upper = vertices.min(axis=0), vertices.max(axis=0)
    with np.errstate(over="ignore"):
        extent = float(np.max(upper - lower))
    if not np.isfinite(extent):
        raise MeshError(
            f"{name}: its extent overflows (coordinates from {float(lower.min()):.3g} to {float(upper.max()):.3g})"
        )
    if not extent > 0:
        raise MeshError(f"{name}: degenerate mesh (all vertices at one point)")
    _check_scale(vertices, extent, name)
    scale = size / extent
    shift = -np.array([0.5 * (lower[0] + upper[0]), 0.5 * (lower[1] + upper[1]), lower[2]])
    placed = (vertices + shift) * scale
    mesh = trimesh.Trimesh(placed, faces, process=False)
    if not float(mesh.area) > MIN_AREA_FRACTION * size * size:
        raise MeshError(f"{name}: zero total surface area (every face is degenerate: its corners are in a line)")
    return mesh


MIN_AREA_FRACTION = 1e-9
"""A placed mesh with less surface area than this times ``size**2`` has none (only zero-area faces)."""
OUTLIER_RATIO = 1e4
"""A vertex farther from the vertices' median than this many times their median distance to it is an outlier
that makes the scale meaningless (the object proper would shrink to nothing)."""


def _check_scale(vertices: NDArray[np.float64], extent: float, name: str) -> None:
    """MeshError when a few far outlier vertices set the extent, not the object (a 1 cm object with one vertex
    at 1e30). A thin object or a sheet is fine: the test is on distances from the median, not on proportions."""
    centre = np.median(vertices, axis=0)
    with np.errstate(over="ignore", invalid="ignore"):
        distance = np.linalg.norm((vertices - centre) / extent, axis=1) * extent
    typical = float(np.median(distance))
    far = distance > OUTLIER_RATIO * typical
    if (typical > 0 and np.any(far)) or not np.all(np.isfinite(distance)):
        k = int(np.count_nonzero(far | ~np.isfinite(distance)))
        raise MeshError(
            f"{name}: {k} far outlier vertex(es) up to {float(np.nanmax(distance)):.3g} from the object, whose "
            f"vertices are typically {typical:.3g} from its centre: its scale would be meaningless"
        )


def sample_surface(mesh: trimesh.Trimesh, n: int = 10000, seed: int = 0) -> NDArray[np.float64]:
    """(n, 3) float64 points uniform over the surface area of ``mesh``, reproducible for a given ``seed``."""
    if not isinstance(n, int | np.integer) or isinstance(n, bool) or n < 1:
        raise ValueError(f"n: must be an integer >= 1, got {n!r}")
    if len(mesh.faces) == 0:
        raise ValueError("mesh: empty mesh (no faces)")
    sampled = trimesh.sample.sample_surface(mesh, int(n), seed=np.random.default_rng(seed))
    return np.asarray(sampled[0], dtype=np.float64)


def turned_about_plate_axis(mesh: trimesh.Trimesh, yaw_deg: float) -> trimesh.Trimesh:
    """A copy of a placed ``mesh`` turned ``yaw_deg`` degrees (counter-clockwise seen from above) about z.

    The turntable axis is z through the plate centre, so the object stays on the plate
    top and keeps its height; only the side that faces a given direction changes.
    Raises MeshError for a non-finite angle.
    """
    if not np.isfinite(yaw_deg):
        raise MeshError(f"yaw: must be finite, got {yaw_deg!r}")
    a = np.radians(yaw_deg)
    c, s = np.cos(a), np.sin(a)
    R_world_object = np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])
    vertices = np.asarray(mesh.vertices, dtype=np.float64) @ R_world_object.T
    return trimesh.Trimesh(vertices, np.asarray(mesh.faces).copy(), process=False)
