"""ROS 2 bags (rosbag2, MCAP or SQLite 3) as scans: the message layout both ways, and the reader of recorded views.

A *scan bag* holds, per view, a depth image (``sensor_msgs/Image``, ``32FC1`` metres or ``16UC1`` millimetres), the
camera's ``sensor_msgs/CameraInfo``, the camera pose in ``/tf`` (and ``/tf_static``) and, optionally,
``sensor_msgs/JointState``. :func:`load_bag` turns such a bag into :class:`planner.types.DepthFrame` s, one per depth
image (with joint states: one per stop of the joints, :func:`still_images`), each posed by the TF chain from the
plate frame (``BagTopics.plate_frame``) to the image's ``frame_id`` at the image's stamp. The camera pose is taken from TF only (a lab's ``robot_state_publisher`` turns the arm's and the
turntable's joint states into TF); the joint states are not run through the arm's kinematics here.

The writer of a session's bag is ``workbench.journal.bag``; both use the names below, so an exported bag plays back
with the default :class:`BagTopics`. ``rosbags`` (the ``ros2`` extra) is imported lazily.
"""

from __future__ import annotations

import json
from collections import defaultdict
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np
from numpy.typing import NDArray

from planner.types import DepthFrame, Intrinsics, Pose

if TYPE_CHECKING:
    from rosbags.typesys.store import Typestore

BAG_SUFFIXES = (".mcap", ".db3")
"""Single-file rosbag2 storages (a rosbag2 folder holds ``metadata.yaml`` and one of these)."""
MAX_BAG_VIEWS = 200
"""A bag may hold at most this many views."""
STILL_NS = 300_000_000
"""A depth image is a view when the joints stood still for this long before it (ns)."""
STILL_RAD = 1e-3
"""Joints within this of each other (rad, or m for a prismatic joint) stand still."""

PLATE_FRAME = "plate"
WORLD_FRAME = "world"
CAMERA_FRAME = "camera_depth_optical_frame"
ARM_BASE_FRAME = "base_link"
PLATE_JOINT = "plate_joint"
DEPTH_TOPIC = "/camera/camera/depth/image_rect_raw"
CAMERA_INFO_TOPIC = "/camera/camera/depth/camera_info"
JOINT_STATES_TOPIC = "/joint_states"
CLOUD_TOPIC = "/nbv/cloud"
SURFACE_TOPIC = "/nbv/surface"
SCAN_TOPIC = "/nbv/scan"
"""A ``std_msgs/String`` holding JSON about the scan (session id, model, source) in bags we write."""


@dataclass(frozen=True)
class BagTopics:
    """Where a bag's scan is: topic names (defaults: ``realsense2_camera`` >= 4.55 and ros2_control's joint states)
    and the frame the views are posed in."""

    depth: str = DEPTH_TOPIC
    """The depth images (``sensor_msgs/Image``, ``32FC1`` metres or ``16UC1`` millimetres)."""
    camera_info: str = CAMERA_INFO_TOPIC
    """The depth camera's ``sensor_msgs/CameraInfo`` (its K gives the intrinsics)."""
    joint_states: str = JOINT_STATES_TOPIC
    """``sensor_msgs/JointState`` of the arm and the plate (optional in a bag; kept for the record)."""
    plate_frame: str = PLATE_FRAME
    """The TF frame of the turntable's plate: the planner's world (objects rest on it)."""

    @staticmethod
    def from_dict(data: dict[str, Any] | None) -> BagTopics:
        """``BagTopics`` from ``{"depth", "camera_info", "joint_states", "plate_frame"}`` (any subset).
        ValueError for an unknown key or a value that is not a non-empty string."""
        data = dict(data or {})
        known = {"depth", "camera_info", "joint_states", "plate_frame"}
        if unknown := sorted(set(data) - known):
            raise ValueError(f"bag topics: unknown key(s) {', '.join(unknown)} (known: {', '.join(sorted(known))})")
        for key, value in data.items():
            if not isinstance(value, str) or not value.strip():
                raise ValueError(f"bag topics: {key} must be a non-empty string, got {value!r}")
        return BagTopics(**data)


@dataclass(frozen=True)
class BagScan:
    """A bag read as a scan: its views, their stamps (ns) and what the bag says about itself (``/nbv/scan``)."""

    frames: tuple[DepthFrame, ...]
    stamps: tuple[int, ...]
    info: dict[str, Any]


def typestore(distro: str = "humble") -> Typestore:
    """The ``rosbags`` type store of ROS 2 ``distro`` (``humble`` or ``jazzy``). ValueError otherwise."""
    from rosbags.typesys import Stores, get_typestore

    stores = {"humble": Stores.ROS2_HUMBLE, "jazzy": Stores.ROS2_JAZZY}
    if distro not in stores:
        raise ValueError(f"ROS 2 distro {distro!r}: 'humble' or 'jazzy'")
    return get_typestore(stores[distro])


def is_bag(path: Path) -> bool:
    """Whether ``path`` is a rosbag2: a ``.mcap`` / ``.db3`` file, or a folder with ``metadata.yaml``."""
    path = Path(path)
    if path.is_file():
        return path.suffix in BAG_SUFFIXES
    return path.is_dir() and (path / "metadata.yaml").is_file()


# ---------------------------------------------------------------------- transforms


def pose_of_transform(t: Any) -> Pose:
    """A ``geometry_msgs/Transform`` as a Pose (``T_parent_child``)."""
    q = t.rotation
    wxyz = np.array([q.w, q.x, q.y, q.z], dtype=np.float64)
    norm = float(np.linalg.norm(wxyz))
    if not np.isfinite(norm) or norm < 1e-9:
        raise ValueError(f"a transform with a zero or non-finite quaternion {wxyz.tolist()}")
    return Pose.from_wxyz(wxyz / norm, [t.translation.x, t.translation.y, t.translation.z])


class TfBuffer:
    """Every transform of a bag's ``/tf`` and ``/tf_static``, looked up by frame pair and time."""

    def __init__(self) -> None:
        self.parent: dict[str, str] = {}
        self.dynamic: dict[str, list[tuple[int, Pose]]] = defaultdict(list)
        self.static: dict[str, Pose] = {}

    def add(self, message: Any, static: bool) -> None:
        for t in message.transforms:
            parent, child = t.header.frame_id.lstrip("/"), t.child_frame_id.lstrip("/")
            self.parent[child] = parent
            pose = pose_of_transform(t.transform)
            if static:
                self.static[child] = pose
            else:
                stamp = int(t.header.stamp.sec) * 1_000_000_000 + int(t.header.stamp.nanosec)
                self.dynamic[child].append((stamp, pose))

    def _edge(self, child: str, stamp: int) -> Pose:
        if child in self.static:
            return self.static[child]
        samples = self.dynamic[child]
        at = [p for s, p in samples if s <= stamp]  # the latest at or before the stamp, else the first after
        return at[-1] if at else min(samples, key=lambda sp: sp[0])[1]

    def _chain(self, frame: str) -> list[str]:
        chain = [frame]
        while chain[-1] in self.parent and len(chain) < 64:
            chain.append(self.parent[chain[-1]])
        return chain

    def lookup(self, target: str, source: str, stamp: int) -> Pose:
        """``T_target_source`` at ``stamp`` (ns). ValueError naming both frames when TF does not connect them."""
        up_source, up_target = self._chain(source), self._chain(target)
        common = next((f for f in up_source if f in up_target), None)
        if common is None:
            known = ", ".join(sorted(set(self.parent) | set(self.parent.values()))) or "none"
            raise ValueError(f"/tf does not connect the frame {target!r} to {source!r} (frames in the bag: {known})")
        T_common_source = Pose.identity()
        for child in up_source[: up_source.index(common)]:
            T_common_source = self._edge(child, stamp) @ T_common_source
        T_common_target = Pose.identity()
        for child in up_target[: up_target.index(common)]:
            T_common_target = self._edge(child, stamp) @ T_common_target
        return T_common_target.inverse() @ T_common_source


# ---------------------------------------------------------------------- images


def depth_of_image(msg: Any) -> NDArray[np.float32]:
    """(H, W) float32 metres (0 = no return) of a ``sensor_msgs/Image``: ``32FC1`` metres (NaN, inf and negative
    values become 0) or ``16UC1`` / ``mono16`` millimetres. ValueError naming the encoding or the bad size."""
    h, w, step = int(msg.height), int(msg.width), int(msg.step)
    data = np.asarray(msg.data, dtype=np.uint8)
    encoding = str(msg.encoding)
    sizes = {"32FC1": 4, "16UC1": 2, "mono16": 2}
    if encoding not in sizes:
        raise ValueError(f"depth image encoding {encoding!r}: expected 32FC1 (metres) or 16UC1 (millimetres)")
    size = sizes[encoding]
    if h <= 0 or w <= 0 or step < w * size or data.size < h * step:
        raise ValueError(f"depth image {w}x{h} ({encoding}, step {step}): {data.size} bytes of data")
    rows = data[: h * step].reshape(h, step)[:, : w * size]
    order = ">" if msg.is_bigendian else "<"
    if size == 4:
        depth = rows.copy().view(f"{order}f4").reshape(h, w).astype(np.float32)
        depth[~np.isfinite(depth) | (depth < 0)] = 0.0
        return depth
    return (rows.copy().view(f"{order}u2").reshape(h, w).astype(np.float32) * np.float32(0.001)).astype(np.float32)


def intrinsics_of_info(msg: Any) -> Intrinsics:
    """The pinhole intrinsics of a ``sensor_msgs/CameraInfo`` (K). ValueError for a zero or non-finite K."""
    k = np.asarray(msg.k, dtype=np.float64).reshape(3, 3)
    fx, fy, cx, cy = k[0, 0], k[1, 1], k[0, 2], k[1, 2]
    if not (np.all(np.isfinite(k)) and fx > 0 and fy > 0):
        raise ValueError(f"camera info: K has no focal length ({k[0].tolist()}, {k[1].tolist()})")
    return Intrinsics(int(msg.width), int(msg.height), float(fx), float(fy), float(cx), float(cy))


# ---------------------------------------------------------------------- reading


def still_images(
    times: list[int], joints: list[tuple[int, NDArray[np.float64]]], settle_ns: int = STILL_NS, tol: float = STILL_RAD
) -> list[int]:
    """Which depth images are views: with no joint states, every one; else the first image of each period in which
    the joints stood still (every joint state of the last ``settle_ns`` within ``tol`` of the latest one), so a bag
    recorded at the camera's rate gives one view per stop of the arm and the plate.

    times: (M,) the images' log times (ns, ascending); joints: (log time ns, (J,) positions) in time order, NaN
    for a joint not heard of yet. Returns indices into ``times``."""
    if not joints:
        return list(range(len(times)))
    stamps = np.array([t for t, _ in joints], dtype=np.int64)
    q_all = np.array([q for _, q in joints], dtype=np.float64)
    keep: list[int] = []
    last: NDArray[np.float64] | None = None
    moved = True
    for i, t in enumerate(times):
        j = int(np.searchsorted(stamps, t, side="right")) - 1
        if j < 0:  # no joint state yet: where the arm is is unknown
            moved = True
            continue
        q = q_all[j]
        lo = int(np.searchsorted(stamps, t - settle_ns, side="left"))
        if _spread(q_all[lo : j + 1] - q) > tol:
            moved = True
            continue
        if moved or last is None or _spread(q - last) > tol:
            keep.append(i)
            last = q
        moved = False
    return keep


def _spread(d: NDArray[np.float64]) -> float:
    """The largest absolute difference in ``d`` (any shape), a joint not heard of (NaN) counting as none."""
    return float(np.nan_to_num(np.abs(d), nan=0.0).max(initial=0.0))


def load_bag(path: str | Path, topics: BagTopics | None = None) -> BagScan:
    """The views of the rosbag2 at ``path`` (a ``.mcap`` / ``.db3`` file or a rosbag2 folder) in time order: one
    per depth image, or, when the bag has joint states, one per stop of the joints (:func:`still_images`).

    ValueError (naming what is missing or wrong) for: not a bag, no depth-image or camera-info topic (or one of
    another type), an unsupported encoding, no camera info message, an image whose size differs from its camera info,
    TF that does not connect the plate frame to the image's frame, no depth image, more than :data:`MAX_BAG_VIEWS`
    views."""
    from rosbags.highlevel import AnyReader, AnyReaderError

    topics = topics or BagTopics()
    path = Path(path)
    if not is_bag(path):
        raise ValueError(f"{path.name}: not a rosbag2 (a .mcap or .db3 file, or a folder with metadata.yaml)")
    expected = {topics.depth: "sensor_msgs/msg/Image", topics.camera_info: "sensor_msgs/msg/CameraInfo"}
    try:
        with AnyReader([path]) as reader:
            types = {c.topic: c.msgtype for c in reader.connections}
            for topic, msgtype in expected.items():
                if topic not in types:
                    have = ", ".join(f"{t} ({types[t]})" for t in sorted(types)) or "none"
                    raise ValueError(f"{path.name}: no topic {topic} ({msgtype}); the bag has: {have}")
                if types[topic] != msgtype:
                    raise ValueError(f"{path.name}: topic {topic} is {types[topic]}, expected {msgtype}")
            wanted = [topics.depth, topics.camera_info, topics.joint_states, "/tf", "/tf_static", SCAN_TOPIC]
            connections = [c for c in reader.connections if c.topic in wanted]
            tf = TfBuffer()
            infos: list[tuple[int, Any]] = []
            image_times: list[int] = []
            joint_log: list[tuple[int, dict[str, float]]] = []
            current: dict[str, float] = {}
            info: dict[str, Any] = {}
            for con, logged, raw in reader.messages(connections=connections):
                if con.topic == topics.depth:  # read in the second pass, only the views
                    image_times.append(int(logged))
                    continue
                msg: Any = reader.deserialize(raw, con.msgtype)
                if con.topic in ("/tf", "/tf_static") and con.msgtype == "tf2_msgs/msg/TFMessage":
                    tf.add(msg, static=con.topic == "/tf_static")
                elif con.topic == topics.camera_info:
                    infos.append((_stamp(msg.header), msg))
                elif con.topic == topics.joint_states and con.msgtype == "sensor_msgs/msg/JointState":
                    current.update(zip(msg.name, (float(v) for v in msg.position), strict=False))
                    joint_log.append((int(logged), dict(current)))
                elif con.topic == SCAN_TOPIC and con.msgtype == "std_msgs/msg/String":
                    info = _scan_info(msg.data)
            if not image_times:
                raise ValueError(f"{path.name}: no message on {topics.depth}")
            if not infos:
                raise ValueError(f"{path.name}: no camera info on {topics.camera_info}")
            names = sorted({n for _, q in joint_log for n in q})
            joints = [(t, np.array([q.get(n, np.nan) for n in names], dtype=np.float64)) for t, q in joint_log]
            views = still_images(image_times, joints)
            if len(views) > MAX_BAG_VIEWS:
                raise ValueError(f"{path.name}: {len(views)} views on {topics.depth}, more than {MAX_BAG_VIEWS}")
            chosen = set(views)
            images: list[tuple[int, Any]] = []
            depth_connections = [c for c in connections if c.topic == topics.depth]
            for n, (con, _, raw) in enumerate(reader.messages(connections=depth_connections)):
                if n in chosen:
                    msg = reader.deserialize(raw, con.msgtype)
                    images.append((n, msg))
    except (AnyReaderError, OSError, KeyError) as exc:
        raise ValueError(f"{path.name}: not a readable rosbag2 ({exc})") from None
    frames, stamps = [], []
    for n, msg in sorted(images, key=lambda im: (_stamp(im[1].header), im[0])):
        stamp = _stamp(msg.header)
        where = f"{path.name}: depth image {n + 1} on {topics.depth}"
        before = [m for s, m in infos if s <= stamp]
        k = intrinsics_of_info(before[-1] if before else infos[0][1])
        try:
            depth = depth_of_image(msg)
        except ValueError as exc:
            raise ValueError(f"{where}: {exc}") from None
        if depth.shape != (k.height, k.width):
            raise ValueError(f"{where}: {depth.shape[1]}x{depth.shape[0]}, its camera info says {k.width}x{k.height}")
        try:
            pose = tf.lookup(topics.plate_frame, msg.header.frame_id.lstrip("/"), stamp)
        except ValueError as exc:
            raise ValueError(f"{where}: {exc}") from None
        frames.append(DepthFrame(depth, pose, k))
        stamps.append(stamp)
    return BagScan(tuple(frames), tuple(stamps), info)


def _stamp(header: Any) -> int:
    return int(header.stamp.sec) * 1_000_000_000 + int(header.stamp.nanosec)


def _scan_info(text: str) -> dict[str, Any]:
    try:
        data = json.loads(text)
    except ValueError:
        return {}
    return data if isinstance(data, dict) else {}
