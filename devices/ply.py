"""Point clouds as PLY files: binary little-endian writer, ASCII/binary reader (x, y, z only)."""

from __future__ import annotations

from pathlib import Path

import numpy as np
from numpy.typing import NDArray

_TYPES = {
    "float": "f4", "float32": "f4", "double": "f8", "float64": "f8",
    "uchar": "u1", "uint8": "u1", "char": "i1", "int8": "i1",
    "ushort": "u2", "uint16": "u2", "short": "i2", "int16": "i2",
    "uint": "u4", "uint32": "u4", "int": "i4", "int32": "i4",
}  # fmt: skip


def write_ply(path: str | Path, points: NDArray[np.float64]) -> None:
    """Write points (N, 3) as a binary little-endian PLY with float32 x, y, z."""
    Path(path).write_bytes(ply_bytes(points))


def ply_bytes(points: NDArray[np.float64]) -> bytes:
    """Points (N, 3) as binary little-endian PLY bytes with float32 x, y, z."""
    pts = np.asarray(points, dtype="<f4").reshape(-1, 3)
    header = (
        "ply\nformat binary_little_endian 1.0\ncomment nbv-workbench\n"
        f"element vertex {len(pts)}\nproperty float x\nproperty float y\nproperty float z\nend_header\n"
    )
    return header.encode("ascii") + pts.tobytes()


def read_ply(path: str | Path) -> NDArray[np.float64]:
    """Read the x, y, z of the vertex element of a PLY point cloud -> (N, 3) float64.

    Raises ValueError for a file that is not a PLY point cloud this reader understands.
    """
    data = Path(path).read_bytes()
    end = data.find(b"end_header")
    if not data.startswith(b"ply") or end < 0:
        raise ValueError(f"{path}: not a PLY file")
    nl = data.find(b"\n", end)
    header = data[:end].decode("ascii", errors="replace").splitlines()
    body = data[nl + 1 :]
    fmt = ""
    count = 0
    props: list[tuple[str, str]] = []
    current = None
    for line in header:
        parts = line.split()
        if not parts:
            continue
        if parts[0] == "format":
            fmt = parts[1]
        elif parts[0] == "element":
            current = parts[1]
            if current == "vertex":
                count = int(parts[2])
        elif parts[0] == "property" and current == "vertex":
            if parts[1] == "list":
                raise ValueError(f"{path}: list properties on vertices are not supported")
            if parts[1] not in _TYPES:
                raise ValueError(f"{path}: unknown property type {parts[1]!r}")
            props.append((parts[2], _TYPES[parts[1]]))
    names = [n for n, _ in props]
    if not {"x", "y", "z"} <= set(names):
        raise ValueError(f"{path}: vertex element lacks x, y, z")
    if fmt == "ascii":
        rows = body.decode("ascii", errors="replace").split("\n")[:count]
        table = np.array([r.split()[: len(props)] for r in rows], dtype=np.float64)
        if table.shape != (count, len(props)):
            raise ValueError(f"{path}: expected {count} vertex rows")
        pts = table[:, [names.index("x"), names.index("y"), names.index("z")]]
    elif fmt in ("binary_little_endian", "binary_big_endian"):
        order = "<" if fmt == "binary_little_endian" else ">"
        dtype = np.dtype([(n, order + t) for n, t in props])
        if len(body) < dtype.itemsize * count:
            raise ValueError(f"{path}: truncated vertex data")
        arr = np.frombuffer(body, dtype=dtype, count=count)
        pts = np.column_stack([arr["x"], arr["y"], arr["z"]]).astype(np.float64)
    else:
        raise ValueError(f"{path}: unsupported PLY format {fmt!r}")
    if not np.all(np.isfinite(pts)):
        raise ValueError(f"{path}: non-finite coordinates")
    return pts
