"""Built-in test objects made in code, placed like a loaded mesh (:func:`devices.mesh.place_on_plate`).

No boolean operations are needed: boxy objects are the boundary of a union of
cells of a rectilinear grid (:func:`grid_surface`, closed and without interior
faces), the mug body is a surface of revolution. So every face is a real
surface of the object, and coverage against surface samples can reach 1 where
the object is visible at all.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from pathlib import Path

import numpy as np
import trimesh
from numpy.typing import NDArray

from devices.mesh import MeshError, UpAxis, load_mesh, place_on_plate

BUILTIN_OBJECTS: dict[str, str] = {
    "l-block": "an L-shaped block with a rectangular hole through its upright (self-occlusion, see-through)",
    "mug": "a cup open at the top with a handle (the inside is hidden except from above)",
    "two-boxes": "a tall and a short box side by side with a narrow gap between them",
    "sphere": "a sphere resting on the plate (an icosphere, 5120 faces)",
    "box": "a 1 : 0.7 : 0.5 cuboid lying flat",
}
"""Built-in object name -> one-line description."""


def grid_surface(
    xs: Sequence[float], ys: Sequence[float], zs: Sequence[float], occupied: NDArray[np.bool_]
) -> trimesh.Trimesh:
    """The closed outer surface of a union of cells of a rectilinear grid.

    xs, ys, zs: increasing cell boundaries, lengths X+1, Y+1, Z+1.
    occupied: (X, Y, Z) bool, which cells are solid.
    Returns a watertight mesh with outward normals: one quad (two triangles) per
    cell face between a solid cell and an empty cell or the outside.
    """
    coords = [np.asarray(c, dtype=np.float64) for c in (xs, ys, zs)]
    occ = np.asarray(occupied, dtype=bool)
    if occ.shape != tuple(len(c) - 1 for c in coords):
        raise ValueError(f"occupied: expected shape {tuple(len(c) - 1 for c in coords)}, got {occ.shape}")
    padded = np.pad(occ, 1)
    quads: list[NDArray[np.float64]] = []
    for a in range(3):
        b, c = (a + 1) % 3, (a + 2) % 3
        lo = np.take(padded, range(padded.shape[a] - 1), axis=a)
        hi = np.take(padded, range(1, padded.shape[a]), axis=a)
        for sign, mask in ((1, lo & ~hi), (-1, hi & ~lo)):
            for idx in np.argwhere(mask):
                i = idx - 1  # cell index in the unpadded grid along b and c; boundary index along a
                plane = coords[a][idx[a]]
                b0, b1 = coords[b][i[b]], coords[b][i[b] + 1]
                c0, c1 = coords[c][i[c]], coords[c][i[c] + 1]
                corners = [(b0, c0), (b1, c0), (b1, c1), (b0, c1)]
                if sign < 0:
                    corners.reverse()
                quad = np.empty((4, 3))
                quad[:, a] = plane
                quad[:, b] = [p[0] for p in corners]
                quad[:, c] = [p[1] for p in corners]
                quads.append(quad)
    vertices = np.concatenate(quads)
    base = 4 * np.arange(len(quads))[:, None]
    faces = np.concatenate([base + np.array([0, 1, 2]), base + np.array([0, 2, 3])])
    mesh = trimesh.Trimesh(vertices, faces, process=False)
    mesh.merge_vertices()
    return mesh


def _l_block() -> trimesh.Trimesh:
    # A slab along +x with an upright at x in [0, 0.3]; the hole runs along x through the upright.
    xs, ys, zs = [0.0, 0.3, 1.0], [0.0, 0.175, 0.325, 0.5], [0.0, 0.3, 0.5, 0.75, 1.0]
    occ = np.zeros((2, 3, 4), dtype=bool)
    occ[:, :, 0] = True  # the slab
    occ[0, :, 1:] = True  # the upright
    occ[0, 1, 2] = False  # the through hole
    return grid_surface(xs, ys, zs, occ)


def _two_boxes() -> trimesh.Trimesh:
    xs, ys, zs = [0.0, 0.4, 0.6, 1.0], [0.0, 0.6], [0.0, 0.6, 1.0]
    occ = np.zeros((3, 1, 2), dtype=bool)
    occ[0, 0, :] = True  # the tall box
    occ[2, 0, 0] = True  # the short box; cells x in [0.4, 0.6] are the gap
    return grid_surface(xs, ys, zs, occ)


def _box() -> trimesh.Trimesh:
    return grid_surface([0.0, 1.0], [0.0, 0.7], [0.0, 0.5], np.ones((1, 1, 1), dtype=bool))


def _sphere() -> trimesh.Trimesh:
    return trimesh.creation.icosphere(subdivisions=4, radius=0.5)


def _mug() -> trimesh.Trimesh:
    R, H, wall, floor = 0.35, 0.8, 0.04, 0.06
    profile = np.array([[0.0, 0.0], [R, 0.0], [R, H], [R - wall, H], [R - wall, floor], [0.0, floor]])
    body = trimesh.creation.revolve(profile, sections=64)
    if body.volume < 0:
        body.invert()
    handle = _handle(center_x=R - wall / 2, center_z=0.45, arc_radius=0.22, tube_radius=0.04)
    faces = np.vstack([body.faces, handle.faces + len(body.vertices)])
    return trimesh.Trimesh(np.vstack([body.vertices, handle.vertices]), faces, process=False)


def _handle(center_x: float, center_z: float, arc_radius: float, tube_radius: float) -> trimesh.Trimesh:
    """Half a torus in the xz plane bulging towards +x; its open ends are buried in the mug wall."""
    nu, nv = 24, 16
    u = np.linspace(-np.pi / 2, np.pi / 2, nu + 1)
    v = np.linspace(0.0, 2 * np.pi, nv, endpoint=False)
    uu, vv = np.meshgrid(u, v, indexing="ij")
    radial = np.stack([np.cos(uu), np.zeros_like(uu), np.sin(uu)], axis=-1)
    centre = np.array([center_x, 0.0, center_z]) + arc_radius * radial
    side = np.array([0.0, 1.0, 0.0])
    vertices = centre + tube_radius * (np.cos(vv)[..., None] * radial + np.sin(vv)[..., None] * side)
    i, j = np.meshgrid(np.arange(nu), np.arange(nv), indexing="ij")
    a = i * nv + j
    b = (i + 1) * nv + j
    c = (i + 1) * nv + (j + 1) % nv
    d = i * nv + (j + 1) % nv
    faces = np.concatenate([np.stack([a, b, c], -1).reshape(-1, 3), np.stack([a, c, d], -1).reshape(-1, 3)])
    mesh = trimesh.Trimesh(vertices.reshape(-1, 3), faces, process=False)
    # Make the normals point away from the tube's centre line.
    tube_centres = centre.reshape(-1, 3)[faces[:, 0]]
    if np.mean(np.einsum("ij,ij->i", mesh.face_normals, mesh.triangles_center - tube_centres)) < 0:
        mesh.invert()
    return mesh


_MAKERS: dict[str, Callable[[], trimesh.Trimesh]] = {
    "l-block": _l_block,
    "mug": _mug,
    "two-boxes": _two_boxes,
    "sphere": _sphere,
    "box": _box,
}


def make_builtin(name: str, size: float = 0.2) -> trimesh.Trimesh:
    """The built-in object ``name`` (a key of :data:`BUILTIN_OBJECTS`), placed on the plate.

    size: largest bounding-box extent, metres. Raises MeshError for an unknown name (listing the known ones).
    """
    maker = _MAKERS.get(name)
    if maker is None:
        raise MeshError(f"unknown built-in object {name!r} (known: {', '.join(BUILTIN_OBJECTS)})")
    return place_on_plate(maker(), up="z", size=size, name=name)


def resolve_model(spec: str, up: UpAxis = "y", size: float = 0.2) -> tuple[str, trimesh.Trimesh]:
    """(display name, placed mesh) for a built-in object name or a mesh file path.

    A built-in name wins over a file of the same name in the working directory;
    ``up`` applies to files only (built-ins are z-up). The display name of a
    file is its stem (``bunny`` for ``.../bunny.obj``).
    Raises MeshError when ``spec`` is neither, or the file cannot be used.
    """
    if spec in BUILTIN_OBJECTS:
        return spec, make_builtin(spec, size)
    path = Path(spec)
    if path.suffix == "" and not path.exists():
        raise MeshError(f"{spec!r} is neither a built-in object ({', '.join(BUILTIN_OBJECTS)}) nor a mesh file")
    return path.stem, load_mesh(path, up=up, size=size)
