"""viser frames decoded with their binary buffers: a point cloud's ``points`` and ``colors`` as numpy arrays.

tests/viewer_wire.py's ``decode_frame`` keeps each array as a placeholder; here the buffers that follow the
compressed msgpack (each at an 8-byte aligned offset, in ``binaryBufferLengths`` order) replace them.
"""

from __future__ import annotations

from typing import Any

import msgspec
import numpy as np
import zstandard


def decode_frame_arrays(data: bytes) -> list[dict[str, Any]]:
    """The messages of one server -> client frame, each binary placeholder replaced by its numpy array."""
    size = int.from_bytes(data[0:8], "little")
    compressed = int.from_bytes(data[8:16], "little")
    inner = zstandard.ZstdDecompressor().decompress(data[16 : 16 + compressed], max_output_size=size)
    decoded = msgspec.msgpack.decode(inner)
    buffers = []
    offset = 16 + compressed
    for n in decoded.get("binaryBufferLengths") or []:
        offset += (8 - offset % 8) % 8
        buffers.append(data[offset : offset + n])
        offset += n
    messages = list(decoded["messages"])
    for message in messages:
        props = message.get("props") or {}
        for key, value in list(props.items()):
            if isinstance(value, dict) and "__binary_index" in value and value["__binary_index"] < len(buffers):
                props[key] = np.frombuffer(buffers[value["__binary_index"]], dtype=np.dtype(value["dtype"]))
    return messages


def point_clouds(frames: list[bytes], name: str) -> list[tuple[np.ndarray, np.ndarray]]:
    """Every ``(points (N, 3) float, colors (N, 3) uint8)`` sent for the point cloud ``name``, oldest first."""
    out = []
    for data in frames:
        for m in decode_frame_arrays(data):
            if m.get("name") == name and "PointCloud" in m.get("type", ""):
                props = m["props"]
                points = np.asarray(props["points"], dtype=np.float64).reshape(-1, 3)
                colors = np.asarray(props["colors"], dtype=np.uint8).reshape(-1, 3)
                out.append((points, colors))
    return out
