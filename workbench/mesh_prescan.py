"""Pre-scans of mesh files whose cost their header or JSON already tells: glTF / GLB and PLY.

A GLB of one 20k-triangle mesh used by 5,000 nodes is a 615 kB file that trimesh flattens into 100 M
triangles before any limit can run. :func:`gltf_counts` reads the JSON only and counts what the flattened
scene would hold: for every node reached from the scene (a node reused under several parents counts once
per path: instancing), its mesh's primitives' triangles (indices / 3 for triangles, n - 2 for strips and
fans) and vertices (POSITION counts). :func:`ply_counts` reads a PLY header's element counts and checks a
binary body can hold them (a header claiming billions of vertices in a small file is refused before a
parser allocates them).
"""

from __future__ import annotations

import json
import struct
from pathlib import Path
from typing import Any

GLB_MAGIC = b"glTF"
MAX_DEPTH = 64
"""Node trees deeper than this are refused (a cycle or a chain bomb)."""
_PLY_SIZES = {
    "char": 1, "uchar": 1, "int8": 1, "uint8": 1, "short": 2, "ushort": 2, "int16": 2, "uint16": 2,
    "int": 4, "uint": 4, "int32": 4, "uint32": 4, "float": 4, "float32": 4, "double": 8, "float64": 8,
}  # fmt: skip


def gltf_json(path: Path) -> dict[str, Any]:
    """The JSON of a .gltf file or of a GLB's first chunk. ValueError when it is neither."""
    data = path.read_bytes()
    if data[:4] == GLB_MAGIC:
        if len(data) < 20:
            raise ValueError("GLB: truncated header")
        length, kind = struct.unpack_from("<II", data, 12)
        if kind != 0x4E4F534A:  # "JSON"
            raise ValueError("GLB: the first chunk is not JSON")
        data = data[20 : 20 + length]
    try:
        document = json.loads(data)
    except (UnicodeDecodeError, json.JSONDecodeError) as exc:
        raise ValueError(f"glTF: the JSON cannot be read ({exc})") from None
    if not isinstance(document, dict):
        raise ValueError("glTF: the JSON is not an object")
    return document


def _primitive_counts(document: dict[str, Any], primitive: dict[str, Any]) -> tuple[int, int]:
    """(vertices, triangles) of one primitive from its accessors' counts."""
    accessors = document.get("accessors") or []

    def count(index: Any) -> int:
        if not isinstance(index, int) or not 0 <= index < len(accessors):
            return 0
        value = accessors[index].get("count", 0) if isinstance(accessors[index], dict) else 0
        return value if isinstance(value, int) and value > 0 else 0

    attributes = primitive.get("attributes") or {}
    vertices = count(attributes.get("POSITION")) if isinstance(attributes, dict) else 0
    corners = count(primitive["indices"]) if "indices" in primitive else vertices
    mode = primitive.get("mode", 4)
    if mode == 4:
        triangles = corners // 3
    elif mode in (5, 6):
        triangles = max(corners - 2, 0)
    else:  # points and lines: no triangles
        triangles = 0
    return vertices, triangles


def gltf_counts(document: dict[str, Any]) -> tuple[int, int, int]:
    """(vertices, triangles, instances) the flattened scene of a glTF document would hold (see the module).

    ValueError for a node tree deeper than MAX_DEPTH (or with a cycle)."""
    meshes = document.get("meshes") or []
    nodes = document.get("nodes") or []
    mesh_counts: list[tuple[int, int]] = []
    for mesh in meshes:
        vertices = triangles = 0
        for primitive in (mesh.get("primitives") or []) if isinstance(mesh, dict) else []:
            if isinstance(primitive, dict):
                v, t = _primitive_counts(document, primitive)
                vertices, triangles = vertices + v, triangles + t
        mesh_counts.append((vertices, triangles))
    memo: dict[int, tuple[int, int, int]] = {}

    def subtree(index: int, depth: int) -> tuple[int, int, int]:
        if depth > MAX_DEPTH:
            raise ValueError(f"glTF: the node tree is deeper than {MAX_DEPTH} (or has a cycle)")
        if index in memo:
            return memo[index]
        node = nodes[index] if isinstance(index, int) and 0 <= index < len(nodes) else {}
        node = node if isinstance(node, dict) else {}
        vertices = triangles = instances = 0
        mesh = node.get("mesh")
        if isinstance(mesh, int) and 0 <= mesh < len(mesh_counts):
            vertices, triangles = mesh_counts[mesh]
            instances = 1
        for child in node.get("children") or []:
            v, t, n = subtree(child, depth + 1)
            vertices, triangles, instances = vertices + v, triangles + t, instances + n
        memo[index] = (vertices, triangles, instances)
        return memo[index]

    scenes = document.get("scenes") or []
    scene = document.get("scene", 0)
    if isinstance(scene, int) and 0 <= scene < len(scenes) and isinstance(scenes[scene], dict):
        roots = scenes[scene].get("nodes") or []
    else:  # no scene: every node that is nobody's child
        children = {c for n in nodes if isinstance(n, dict) for c in n.get("children") or []}
        roots = [i for i in range(len(nodes)) if i not in children]
    total = [0, 0, 0]
    for root in roots:
        for k, value in enumerate(subtree(root, 0)):
            total[k] += value
    if not roots and not nodes:  # meshes without nodes: trimesh loads each once
        total = [sum(v for v, _ in mesh_counts), sum(t for _, t in mesh_counts), len(mesh_counts)]
    return total[0], total[1], total[2]


def ply_counts(path: Path) -> tuple[int, int, str | None]:
    """(vertices, faces) a PLY header declares, and a reason when a binary body is too short to hold them."""
    elements: list[tuple[str, int, list[list[str]]]] = []
    fmt = "ascii"
    with path.open("rb") as fh:
        if fh.readline().strip() != b"ply":
            return 0, 0, None  # not PLY as we know it: the reader says what is wrong
        for _ in range(10_000):
            line = fh.readline()
            if not line:
                return 0, 0, None
            words = line.decode("latin-1").split()
            if not words:
                continue
            if words[0] == "format" and len(words) > 1:
                fmt = words[1]
            elif words[0] == "element" and len(words) == 3:
                try:
                    elements.append((words[1], int(words[2]), []))
                except ValueError:
                    return 0, 0, None
            elif words[0] == "property" and elements:
                elements[-1][2].append(words[1:])
            elif words[0] == "end_header":
                break
        body = path.stat().st_size - fh.tell()
    counts = {name: count for name, count, _ in elements}
    short = None
    if fmt.startswith("binary"):
        least = 0  # each element's smallest size: its fixed properties, a list's count byte(s)
        for _, count, properties in elements:
            row = sum(_PLY_SIZES.get(p[1] if p[0] == "list" else p[0], 1) for p in properties if p)
            least += count * row
        if least > body:
            short = f"its header declares {least} bytes of elements, but the file holds {body}"
    return counts.get("vertex", 0), counts.get("face", 0), short
