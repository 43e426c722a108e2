"""The 3D viewer's websocket, spoken from Python: decode viser's frames, connect as a raw client, click.

Used by the scene and security tests (a raw client with and without a ticket, with a foreign Origin), by the
browser tests (frames captured from Chromium's websockets) and by benchmarks/bench_scene.py (bytes per frame).

viser's server -> client frame: [8 B msgpack size][8 B zstd size][zstd(msgpack)][padding][binary buffers];
the msgpack is ``{"messages": [...], "binaryBufferLengths": [...]}``, each message a dict with ``type`` and,
for scene nodes, ``name``. Client -> server messages are plain msgpack dicts with ``type``.
"""

from __future__ import annotations

import contextlib
import threading
import time
from typing import Any

import msgspec
import viser
import websockets.sync.client
import zstandard
from websockets.typing import Subprotocol

SCENE_PREFIXES = ("/map", "/ellipsoids", "/gmm", "/candidates", "/nbv", "/selected", "/views", "/cloud",
                  "/context/bbox", "/context/sectors", "/context/turntable", "/context/mesh", "/context/session", "/override", "/surface", "/clusters", "/tour")  # fmt: skip
"""Node names that only a session draws."""


def decode_frame(data: bytes) -> list[dict[str, Any]]:
    """The messages of one server -> client frame. An array sent as a binary buffer stays the placeholder
    ``{"__binary_index": i, "dtype": ...}``, with ``"nbytes"``: its buffer's length, added."""
    size = int.from_bytes(data[0:8], "little")
    compressed = int.from_bytes(data[8:16], "little")
    inner = zstandard.ZstdDecompressor().decompress(data[16 : 16 + compressed], max_output_size=size)
    decoded = msgspec.msgpack.decode(inner)
    lengths = decoded.get("binaryBufferLengths") or []
    for message in decoded["messages"]:
        for value in (message.get("props") or {}).values():
            if isinstance(value, dict) and "__binary_index" in value and value["__binary_index"] < len(lengths):
                value["nbytes"] = int(lengths[value["__binary_index"]])
    return list(decoded["messages"])


def session_nodes(messages: list[dict[str, Any]]) -> set[str]:
    """Names of session-drawn scene nodes created by these messages."""
    out = set()
    for m in messages:
        name = m.get("name")
        if isinstance(name, str) and m.get("type", "").endswith("Message") and name.startswith(SCENE_PREFIXES):
            out.add(name)
    return out


def encode(message: dict[str, Any]) -> bytes:
    return msgspec.msgpack.encode(message)


def camera_message() -> dict[str, Any]:
    """The first message a viser client sends (viser counts a client as connected once it arrives)."""
    return {
        "type": "ViewerCameraMessage", "wxyz": (1.0, 0.0, 0.0, 0.0), "position": (0.9, -0.8, 0.7), "fov": 0.9,
        "near": 0.01, "far": 100.0, "image_height": 600, "image_width": 800, "look_at": (0.0, 0.0, 0.0),
        "up_direction": (0.0, 0.0, 1.0),
    }  # fmt: skip


def click_message(name: str, index: int, owner: str = "") -> dict[str, Any]:
    """A click on instance ``index`` of node ``name``; ``owner``: the owner stamp of the clicked node's messages
    (a client's own scene stamps its client id, the shared scene "")."""
    return {
        "type": "SceneNodeClickMessage", "name": name, "instance_index": index, "ray_origin": (0.0, 0.0, 1.0),
        "ray_direction": (0.0, 0.0, -1.0), "screen_pos": (0.5, 0.5), "modifier": None, "owner": owner,
    }  # fmt: skip


class RawViewer:
    """A viser client without a browser: connects, records every frame (bytes and messages), sends messages.

    url: ``ws://host:port/`` (+ ``?ticket=...``); origin: the Origin header (None: none).
    """

    def __init__(self, url: str, origin: str | None) -> None:
        self.frames: list[tuple[float, int, list[dict[str, Any]]]] = []
        self.closed: tuple[int, str] | None = None
        self._lock = threading.Lock()
        self.ws = websockets.sync.client.connect(
            url, origin=origin, subprotocols=[Subprotocol(f"viser-v{viser.__version__}")],  # type: ignore[arg-type]
            compression=None, max_size=None, proxy=None,
        )  # fmt: skip
        self._thread = threading.Thread(target=self._read, daemon=True)
        self._thread.start()
        self.send(camera_message())

    def _read(self) -> None:
        try:
            for data in self.ws:
                assert isinstance(data, bytes)
                with self._lock:
                    self.frames.append((time.perf_counter(), len(data), decode_frame(data)))
        except websockets.exceptions.ConnectionClosed:
            pass
        rcvd = self.ws.protocol.close_rcvd
        self.closed = (rcvd.code, rcvd.reason) if rcvd is not None else (1006, "")

    def send(self, message: dict[str, Any]) -> None:
        with contextlib.suppress(websockets.exceptions.ConnectionClosed):
            self.ws.send(encode(message))

    def messages(self) -> list[dict[str, Any]]:
        with self._lock:
            return [m for _, _, ms in self.frames for m in ms]

    def bytes_since(self, mark: int) -> int:
        """Bytes received in frames after the first ``mark`` frames."""
        with self._lock:
            return sum(n for _, n, _ in self.frames[mark:])

    def mark(self) -> int:
        with self._lock:
            return len(self.frames)

    def close(self) -> None:
        self.ws.close()
        self._thread.join(timeout=5)


def wait_for(predicate: Any, timeout: float = 10.0, interval: float = 0.02) -> Any:
    """Poll ``predicate`` until it returns something truthy (tests only; never while a page must get events)."""
    deadline = time.monotonic() + timeout
    while True:
        value = predicate()
        if value or time.monotonic() > deadline:
            return value
        time.sleep(interval)


def owner_of(messages: list[dict[str, Any]], name: str) -> str:
    """The owner stamp of the last message that created node ``name`` ("" when none)."""
    owners = [m.get("owner", "") for m in messages if m.get("name") == name and "props" in m]
    return str(owners[-1]) if owners else ""


def session_labels(messages: list[dict[str, Any]]) -> set[str]:
    """Texts of the ``/context/session`` labels created by these messages ("session ID")."""
    return {
        m["props"]["text"] for m in messages if m.get("type") == "LabelMessage" and m.get("name") == "/context/session"
    }
