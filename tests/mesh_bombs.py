"""Mesh files that cost far more to load than their size, for the tests and benchmarks/bench_mesh_bombs.py."""

from __future__ import annotations

import json
import struct

import numpy as np


def instancing_glb(nodes: int, triangles: int = 20_000) -> bytes:
    """A GLB with one mesh of about ``triangles`` triangles (a grid) used by ``nodes`` nodes: a few hundred kB that
    a flattening loader turns into ``nodes * triangles`` triangles."""
    side = int(np.ceil(np.sqrt(triangles / 2))) + 1
    u, v = np.meshgrid(np.arange(side, dtype=np.float32), np.arange(side, dtype=np.float32))
    positions = np.column_stack([u.ravel(), v.ravel(), np.zeros(side * side, np.float32)]) / side
    quads = np.array(
        [[i * side + j, i * side + j + 1, (i + 1) * side + j] for i in range(side - 1) for j in range(side - 1)]
    )
    upper = quads + np.array([1, side, side - 1])
    indices = np.concatenate([quads, upper])[:triangles].astype(np.uint32).ravel()
    index_bytes, position_bytes = indices.tobytes(), positions.astype(np.float32).tobytes()
    binary = index_bytes + position_bytes
    document = {
        "asset": {"version": "2.0"},
        "scene": 0,
        "scenes": [{"nodes": list(range(nodes))}],
        "nodes": [{"mesh": 0, "translation": [float(i % 100), float(i // 100), 0.0]} for i in range(nodes)],
        "meshes": [{"primitives": [{"attributes": {"POSITION": 1}, "indices": 0, "mode": 4}]}],
        "buffers": [{"byteLength": len(binary)}],
        "bufferViews": [
            {"buffer": 0, "byteOffset": 0, "byteLength": len(index_bytes), "target": 34963},
            {"buffer": 0, "byteOffset": len(index_bytes), "byteLength": len(position_bytes), "target": 34962},
        ],
        "accessors": [
            {"bufferView": 0, "componentType": 5125, "count": int(indices.size), "type": "SCALAR"},
            {
                "bufferView": 1,
                "componentType": 5126,
                "count": len(positions),
                "type": "VEC3",
                "min": positions.min(axis=0).tolist(),
                "max": positions.max(axis=0).tolist(),
            },
        ],
    }
    text = json.dumps(document).encode()
    text += b" " * (-len(text) % 4)
    binary += b"\0" * (-len(binary) % 4)
    chunks = struct.pack("<II", len(text), 0x4E4F534A) + text + struct.pack("<II", len(binary), 0x004E4942) + binary
    return struct.pack("<III", 0x46546C67, 2, 12 + len(chunks)) + chunks


def ply_header_bomb(vertices: int = 1_500_000, faces: int = 1_500_000) -> bytes:
    """A binary PLY whose header declares ``vertices`` and ``faces`` (within the limits) and whose body is empty."""
    header = (
        "ply\nformat binary_little_endian 1.0\n"
        f"element vertex {vertices}\nproperty float x\nproperty float y\nproperty float z\n"
        f"element face {faces}\nproperty list uchar int vertex_indices\nend_header\n"
    )
    return header.encode()


def obj_parser_bomb(lines: int = 327, corners: int = 4000) -> bytes:
    """An OBJ of 4 vertices and ``lines`` polygons of ``corners`` indices (5 MB that triangulate into 1.3 M
    overlapping triangles on 4 vertices: a ray-casting and parser bomb)."""
    face = "f " + " ".join(str(1 + i % 4) for i in range(corners)) + "\n"
    return ("v 0 0 0\nv 1 0 0\nv 1 1 0\nv 0 1 1\n" + face * lines).encode()


def obj_slow_parse(triangles: int = 1_900_000) -> bytes:
    """An OBJ within the pre-scan's limits that takes a parser many seconds (1.9 M triangles, 17 MB) and uses
    only 3 of its vertices: refused after loading (triangles per vertex), by the reader's child."""
    vertices = triangles // 8
    return b"".join([b"v 0 0 0\nv 1 0 0\nv 0 1 0\n" * (vertices // 3), b"f 1 2 3\n" * triangles])
