"""A journaled session as a ROS 2 bag (rosbag2, MCAP or SQLite 3) that ``ros2 bag play`` feeds to RViz or Foxglove.

Per kept view (the ``capture`` events after discards), stamped with the capture's time:

- ``/camera/camera/depth/image_rect_raw``: ``sensor_msgs/Image``, ``32FC1`` metres (0 = no return): the journal's
  float32 depth image, byte for byte; frame ``camera_depth_optical_frame`` (OpenCV axes, as ROS optical frames);
- ``/camera/camera/depth/camera_info``: ``sensor_msgs/CameraInfo`` (K, P, identity R, ``plumb_bob`` with zero
  distortion: the journal's frames are rectified);
- ``/tf``: ``world`` -> ``plate`` (the plate angle about z) and ``plate`` -> ``camera_depth_optical_frame`` (the
  frame's pose as captured, before registration: the pose that goes with the image);
- ``/joint_states``: the arm's joints and ``plate_joint`` (sessions on a URDF arm; the reach sphere has no joints).

Per frame kept from the move to a view (capture during moves: the event's ``move_frames``), stamped within its move
(:func:`move_stamps`), on their own topics, so the views' topic keeps one image per view (``load_bag`` replays every
image of a bag without joint states as a view):

- ``/nbv/move/depth/image_rect_raw`` and ``/nbv/move/depth/camera_info``: as the views' image and camera info;
- ``/tf``: ``plate`` -> ``camera_depth_optical_frame`` at the frame's stamp, its pose as captured (as for the views);
- ``/nbv/move/registered_pose``: ``geometry_msgs/PoseStamped`` in ``plate``, the registered pose the map used.

Once: ``/tf_static`` ``world`` -> ``base_link`` (the arm's base; transient-local QoS, so a late RViz gets it) and
``/nbv/scan`` (``std_msgs/String``, JSON: session, model, source). At the end: ``/nbv/cloud`` (the registered cloud,
``sensor_msgs/PointCloud2`` x, y, z float32, frame ``plate``) and ``/nbv/surface`` (the reconstructed surface, a
``visualization_msgs/Marker`` TRIANGLE_LIST in ``plate``). The reader (``devices.rosbag.load_bag``) reads the views
back with its default topics. docs/bags.md is the user's guide.
"""

from __future__ import annotations

import json
import shutil
import tempfile
import time
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Literal

import numpy as np
from numpy.typing import NDArray

from devices.config import DeviceConfig
from devices.motion import rz
from devices.rosbag import (
    ARM_BASE_FRAME,
    CAMERA_FRAME,
    CAMERA_INFO_TOPIC,
    CLOUD_TOPIC,
    DEPTH_TOPIC,
    JOINT_STATES_TOPIC,
    PLATE_FRAME,
    PLATE_JOINT,
    SCAN_TOPIC,
    SURFACE_TOPIC,
    WORLD_FRAME,
    typestore,
)
from planner import DepthFrame, Pose
from planner.config import from_dict
from workbench.journal.discard import without_discarded
from workbench.journal.rebuild import rebuild, replay_cell
from workbench.journal.store import Journal, read_journal
from workbench.journal.surface import surface_of_journal
from workbench.surface.export import layer_mesh

MOVE_DEPTH_TOPIC = "/nbv/move/depth/image_rect_raw"
"""The depth images of the frames kept during moves (``sensor_msgs/Image``, ``32FC1``, as the views')."""
MOVE_CAMERA_INFO_TOPIC = "/nbv/move/depth/camera_info"
"""Their camera infos (the image topic's sibling, where RViz's DepthCloud and ``depth_image_proc`` look)."""
MOVE_POSE_TOPIC = "/nbv/move/registered_pose"
"""Their registered poses (``geometry_msgs/PoseStamped``, frame ``plate``): the poses the map used."""
STORAGES = {".mcap": "MCAP", ".db3": "SQLITE3"}
"""The file suffixes ``export_bag`` writes and their rosbag2 storage plugins."""
BAG_VERSIONS: dict[str, Literal[8, 9]] = {"humble": 8, "jazzy": 9}
"""The rosbag2 format version written per distro: 8 stores the QoS profiles with numeric enums (the form Humble
parses), 9 with names (Jazzy's). The single storage file carries the message definitions either way."""


@dataclass(frozen=True)
class BagExport:
    """What ``export_bag`` wrote: the file, its size, the views, the cloud's points and the surface's triangles."""

    path: Path
    bytes: int
    views: int
    points: int
    triangles: int
    seconds: float
    move_frames: int = 0
    """The frames kept during moves that went in (capture during moves; 0 without)."""


def _ns(seconds: float) -> int:
    return round(float(seconds) * 1e9)


def move_stamps(
    view_stamps: list[int], moves: list[list[float]], move_seconds: list[float], first: int | None
) -> list[list[int]]:
    """The stamps (ns, the views' clock) of the frames kept from the move to each view: the move ends at its view's
    stamp and starts ``move_seconds`` before it, so a frame ``t`` seconds into the move is stamped
    ``view - move_seconds + t``. The move never starts before the previous view (or ``first``, the session's start,
    for the first view's move): a window shorter than the move (a simulated move is instant, so its views are closer
    in wall time than the move is long) is shared out in proportion to ``t``. Each frame lies strictly after the
    previous view and its move's earlier frames and strictly before its view (as long as the window has room: one
    ns per frame).

    view_stamps: the views' stamps (strictly increasing); moves: per view, the frames' ``t`` (seconds since the move
    started, in stamp order); move_seconds: per view, the move's modelled duration."""
    out: list[list[int]] = []
    for i, (view, ts, seconds) in enumerate(zip(view_stamps, moves, move_seconds, strict=True)):
        if not ts:
            out.append([])
            continue
        duration = _ns(max(float(seconds), max(ts), 0.0))
        lo = view_stamps[i - 1] if i > 0 else first
        start = view - duration if lo is None else max(lo, view - duration)
        scale = (view - start) / duration if duration > 0 else 0.0
        stamps: list[int] = []
        previous = start - 1 if lo is None else lo
        for t in ts:
            stamp = start + round(max(float(t), 0.0) * 1e9 * scale)
            stamp = min(max(stamp, previous + 1), view - 1)
            stamps.append(stamp)
            previous = stamp
        out.append(stamps)
    return out


class _Messages:
    """The message constructors of one ROS 2 type store."""

    def __init__(self, distro: str) -> None:
        self.store = typestore(distro)
        self.t: dict[str, Any] = dict(self.store.types)

    def header(self, stamp: int, frame: str) -> Any:
        time_msg = self.t["builtin_interfaces/msg/Time"](sec=stamp // 1_000_000_000, nanosec=stamp % 1_000_000_000)
        return self.t["std_msgs/msg/Header"](stamp=time_msg, frame_id=frame)

    def transform(self, stamp: int, parent: str, child: str, pose: Pose) -> Any:
        t = self.t
        w, x, y, z = (float(v) for v in pose.wxyz)
        px, py, pz = (float(v) for v in pose.translation)
        return t["geometry_msgs/msg/TransformStamped"](
            header=self.header(stamp, parent),
            child_frame_id=child,
            transform=t["geometry_msgs/msg/Transform"](
                translation=t["geometry_msgs/msg/Vector3"](x=px, y=py, z=pz),
                rotation=t["geometry_msgs/msg/Quaternion"](x=x, y=y, z=z, w=w),
            ),
        )

    def pose_stamped(self, stamp: int, frame: str, pose: Pose) -> Any:
        t = self.t
        w, x, y, z = (float(v) for v in pose.wxyz)
        px, py, pz = (float(v) for v in pose.translation)
        return t["geometry_msgs/msg/PoseStamped"](
            header=self.header(stamp, frame),
            pose=t["geometry_msgs/msg/Pose"](
                position=t["geometry_msgs/msg/Point"](x=px, y=py, z=pz),
                orientation=t["geometry_msgs/msg/Quaternion"](x=x, y=y, z=z, w=w),
            ),
        )

    def tf(self, transforms: list[Any]) -> Any:
        return self.t["tf2_msgs/msg/TFMessage"](transforms=transforms)

    def image(self, stamp: int, frame: DepthFrame) -> Any:
        depth = np.ascontiguousarray(frame.depth, dtype="<f4")
        h, w = depth.shape
        data = depth.view(np.uint8).reshape(-1)
        return self.t["sensor_msgs/msg/Image"](
            header=self.header(stamp, CAMERA_FRAME),
            height=h,
            width=w,
            encoding="32FC1",
            is_bigendian=0,
            step=w * 4,
            data=data,
        )

    def camera_info(self, stamp: int, frame: DepthFrame) -> Any:
        k = frame.intrinsics
        K = np.array([k.fx, 0.0, k.cx, 0.0, k.fy, k.cy, 0.0, 0.0, 1.0], dtype=np.float64)
        P = np.array([k.fx, 0.0, k.cx, 0.0, 0.0, k.fy, k.cy, 0.0, 0.0, 0.0, 1.0, 0.0], dtype=np.float64)
        roi = self.t["sensor_msgs/msg/RegionOfInterest"](x_offset=0, y_offset=0, height=0, width=0, do_rectify=False)
        return self.t["sensor_msgs/msg/CameraInfo"](
            header=self.header(stamp, CAMERA_FRAME),
            height=k.height,
            width=k.width,
            distortion_model="plumb_bob",
            d=np.zeros(5, dtype=np.float64),
            k=K,
            r=np.eye(3, dtype=np.float64).reshape(-1),
            p=P,
            binning_x=0,
            binning_y=0,
            roi=roi,
        )

    def joint_state(self, stamp: int, names: list[str], positions: list[float]) -> Any:
        return self.t["sensor_msgs/msg/JointState"](
            header=self.header(stamp, ""),
            name=names,
            position=np.array(positions, dtype=np.float64),
            velocity=np.zeros(0, dtype=np.float64),
            effort=np.zeros(0, dtype=np.float64),
        )

    def cloud(self, stamp: int, points: NDArray[np.float64]) -> Any:
        pts = np.ascontiguousarray(points, dtype="<f4").reshape(-1, 3)
        field = self.t["sensor_msgs/msg/PointField"]
        fields = [field(name=n, offset=4 * i, datatype=7, count=1) for i, n in enumerate("xyz")]  # 7: FLOAT32
        return self.t["sensor_msgs/msg/PointCloud2"](
            header=self.header(stamp, PLATE_FRAME),
            height=1,
            width=len(pts),
            fields=fields,
            is_bigendian=False,
            point_step=12,
            row_step=12 * len(pts),
            data=pts.view(np.uint8).reshape(-1),
            is_dense=True,
        )

    def marker(self, stamp: int, triangles: NDArray[np.float64]) -> Any:
        """A TRIANGLE_LIST of ``triangles`` ((3 F, 3) float64, each three rows one triangle) in the plate frame."""
        t = self.t
        fields = t["visualization_msgs/msg/Marker"].__dataclass_fields__
        point = t["geometry_msgs/msg/Point"]
        values: dict[str, Any] = {
            "header": self.header(stamp, PLATE_FRAME),
            "ns": "nbv_surface",
            "id": 0,
            "type": 11,  # TRIANGLE_LIST
            "action": 0,  # ADD
            "pose": t["geometry_msgs/msg/Pose"](
                position=point(x=0.0, y=0.0, z=0.0),
                orientation=t["geometry_msgs/msg/Quaternion"](x=0.0, y=0.0, z=0.0, w=1.0),
            ),
            "scale": t["geometry_msgs/msg/Vector3"](x=1.0, y=1.0, z=1.0),
            "color": t["std_msgs/msg/ColorRGBA"](r=0.85, g=0.65, b=0.3, a=1.0),
            "lifetime": t["builtin_interfaces/msg/Duration"](sec=0, nanosec=0),
            "frame_locked": False,
            "points": [point(x=float(x), y=float(y), z=float(z)) for x, y, z in triangles],
            "colors": [],
            "texture_resource": "",
            "texture": t["sensor_msgs/msg/CompressedImage"](
                header=self.header(0, ""), format="", data=np.zeros(0, dtype=np.uint8)
            ),
            "uv_coordinates": [],
            "text": "",
            "mesh_resource": "",
            "mesh_file": t["visualization_msgs/msg/MeshFile"](filename="", data=np.zeros(0, dtype=np.uint8)),
            "mesh_use_embedded_materials": False,
        }
        return t["visualization_msgs/msg/Marker"](**{k: v for k, v in values.items() if k in fields})


def _joint_names(devices: DeviceConfig | None, count: int) -> list[str]:
    """The arm's joint names from its URDF model; ``joint_1`` .. when the model cannot be loaded."""
    if devices is not None:
        try:
            from devices.arm.model import load_arm

            names = list(load_arm(devices.cell.arm, devices.cell.arm.mount).joint_names)
            if len(names) == count:
                return names
        except Exception:  # a name is a label: any failure falls back to numbered joints
            pass
    return [f"joint_{i + 1}" for i in range(count)]


def _cloud_and_surface(
    journal: Journal, cloud: NDArray[np.float64] | None
) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """The registered cloud ((N, 3) float64, plate frame: ``cloud``, else that of the journal's replay) and the
    surface as triangles ((3 F, 3) float64, the page's layer budget; (0, 3) when there is no surface)."""
    if cloud is None:
        cloud = rebuild(journal, replay_cell(journal)).planner.cloud
    cloud = np.asarray(cloud, dtype=np.float64).reshape(-1, 3)
    update = surface_of_journal(journal).update
    mesh = None if update is None else update.mesh
    if mesh is None or len(mesh.faces) == 0:
        return cloud, np.zeros((0, 3))
    layer = layer_mesh(mesh)
    return cloud, np.asarray(layer.vertices)[np.asarray(layer.faces).reshape(-1)]


def export_bag(
    session_dir: str | Path, out: str | Path, distro: str = "humble", cloud: NDArray[np.float64] | None = None
) -> BagExport:
    """Write the journaled session in ``session_dir`` to the rosbag2 file ``out`` (``.mcap``: MCAP, ``.db3``:
    SQLite 3; replaced when it exists) with ``distro``'s message definitions (``humble`` or ``jazzy``).

    cloud: the session's registered cloud ((N, 3) float64) when the caller holds it (a live session); None:
    replayed from the journal (``nbv replay``'s rebuild, seconds: it re-makes every plan).

    ValueError (nothing written) for another suffix, an unreadable journal or a session without a view."""
    from rosbags.interfaces import Qos, QosDurability, QosHistory, QosLiveliness, QosReliability, QosTime
    from rosbags.rosbag2 import Writer
    from rosbags.rosbag2.enums import StoragePlugin

    clock = time.perf_counter()
    out = Path(out)
    suffix = out.suffix.lower()
    if suffix not in STORAGES:
        raise ValueError(f"{out.name}: a bag is a .mcap (MCAP) or .db3 (SQLite 3) file")
    journal = read_journal(session_dir)
    captures = [e for e in without_discarded(journal.events) if e.get("kind") == "capture" and e.get("frame")]
    if not captures:
        raise ValueError(f"session {journal.session_id}: no view to export")
    frames = [journal.frame(e) for e in captures]
    try:
        devices: DeviceConfig | None = from_dict(DeviceConfig, journal.header["devices"])
    except (KeyError, TypeError, ValueError):
        devices = None
    cloud, triangles = _cloud_and_surface(journal, cloud)
    m = _Messages(distro)
    store = m.store
    stamps = [_ns(e["time"]) for e in captures]
    for i in range(1, len(stamps)):  # strictly increasing, whatever the clock did
        stamps[i] = max(stamps[i], stamps[i - 1] + 1)
    moves = [journal.move_frames(e) for e in captures]  # (frame as captured, registered pose), in stamp order
    move_ts = [[float(f["t"]) for f in e.get("move_frames") or []] for e in captures]
    move_seconds = [
        float(e.get("move_seconds") or (e.get("move_capture") or {}).get("move_seconds") or 0.0) for e in captures
    ]
    started = journal.header.get("time")
    on_moves = move_stamps(stamps, move_ts, move_seconds, None if started is None else _ns(started))
    first = min([stamps[0], *(s for m in on_moves for s in m)])
    arms = [(e.get("device_state") or {}).get("arm") for e in captures]
    joints = next((len(a["q"]) for a in arms if isinstance(a, dict) and isinstance(a.get("q"), list)), 0)
    names = [*_joint_names(devices, joints), PLATE_JOINT] if joints else []
    latched = Qos(
        QosHistory.KEEP_LAST, 1, QosReliability.RELIABLE, QosDurability.TRANSIENT_LOCAL,
        QosTime(0, 0), QosTime(0, 0), QosLiveliness.AUTOMATIC, QosTime(0, 0), False,
    )  # fmt: skip

    out.parent.mkdir(parents=True, exist_ok=True)
    work = Path(tempfile.mkdtemp(prefix=f".{out.name}.", dir=out.parent))
    try:
        folder = work / "bag"
        plugin = getattr(StoragePlugin, STORAGES[suffix])
        with Writer(folder, version=BAG_VERSIONS[distro], storage_plugin=plugin) as w:

            def conn(topic: str, msgtype: str, qos: list[Any] | None = None) -> Any:
                return w.add_connection(topic, msgtype, typestore=store, offered_qos_profiles=qos or [])

            c_scan = conn(SCAN_TOPIC, "std_msgs/msg/String", [latched])
            c_static = conn("/tf_static", "tf2_msgs/msg/TFMessage", [latched])
            c_tf = conn("/tf", "tf2_msgs/msg/TFMessage")
            c_image = conn(DEPTH_TOPIC, "sensor_msgs/msg/Image")
            c_info = conn(CAMERA_INFO_TOPIC, "sensor_msgs/msg/CameraInfo")
            c_joints = conn(JOINT_STATES_TOPIC, "sensor_msgs/msg/JointState") if names else None
            c_moves = None  # capture during moves: image, camera info, registered pose
            if any(moves):
                c_moves = (
                    conn(MOVE_DEPTH_TOPIC, "sensor_msgs/msg/Image"),
                    conn(MOVE_CAMERA_INFO_TOPIC, "sensor_msgs/msg/CameraInfo"),
                    conn(MOVE_POSE_TOPIC, "geometry_msgs/msg/PoseStamped"),
                )
            c_cloud = conn(CLOUD_TOPIC, "sensor_msgs/msg/PointCloud2", [latched])
            c_surface = conn(SURFACE_TOPIC, "visualization_msgs/msg/Marker", [latched])

            def put(c: Any, stamp: int, msg: Any) -> None:
                w.write(c, stamp, store.serialize_cdr(msg, msg.__msgtype__))

            scan = {
                "session": journal.session_id,
                "model": journal.header.get("model", {}),
                "source": journal.header.get("source", {}),
                "views": len(frames),
                "frames": {"plate": PLATE_FRAME, "world": WORLD_FRAME, "camera": CAMERA_FRAME},
            }
            if c_moves is not None:
                scan["move_frames"] = sum(len(m) for m in moves)
            put(c_scan, first, store.types["std_msgs/msg/String"](data=json.dumps(scan)))
            base = Pose.identity()
            if devices is not None:
                base_xyz = devices.cell.arm.mount if devices.cell.kinematics == "urdf" else devices.cell.arm_base
                base = Pose.from_wxyz([1.0, 0.0, 0.0, 0.0], list(base_xyz))
            put(c_static, first, m.tf([m.transform(first, WORLD_FRAME, ARM_BASE_FRAME, base)]))
            for stamp, frame, arm, move, move_at in zip(stamps, frames, arms, moves, on_moves, strict=True):
                for at, (move_frame, T_world_camera) in zip(move_at, move, strict=True):
                    if c_moves is None:
                        break
                    c_move, c_move_info, c_move_pose = c_moves
                    put(c_tf, at, m.tf([m.transform(at, PLATE_FRAME, CAMERA_FRAME, move_frame.T_world_camera)]))
                    put(c_move, at, m.image(at, move_frame))
                    put(c_move_info, at, m.camera_info(at, move_frame))
                    put(c_move_pose, at, m.pose_stamped(at, PLATE_FRAME, T_world_camera))
                angle = float(arm["angle"]) if isinstance(arm, dict) and "angle" in arm else 0.0
                T_world_plate = rz(angle)
                put(
                    c_tf,
                    stamp,
                    m.tf(
                        [
                            m.transform(stamp, WORLD_FRAME, PLATE_FRAME, T_world_plate),
                            m.transform(stamp, PLATE_FRAME, CAMERA_FRAME, frame.T_world_camera),
                        ]
                    ),
                )
                put(c_image, stamp, m.image(stamp, frame))
                put(c_info, stamp, m.camera_info(stamp, frame))
                if c_joints is not None and isinstance(arm, dict) and isinstance(arm.get("q"), list):
                    put(c_joints, stamp, m.joint_state(stamp, names, [*map(float, arm["q"]), angle]))
            end = stamps[-1] + 1
            put(c_cloud, end, m.cloud(end, cloud))
            put(c_surface, end, m.marker(end, triangles))
        written = next(p for p in folder.iterdir() if p.suffix == suffix)
        written.replace(out)
    finally:
        shutil.rmtree(work, ignore_errors=True)
    return BagExport(
        out,
        out.stat().st_size,
        len(frames),
        len(cloud),
        len(triangles) // 3,
        time.perf_counter() - clock,
        sum(len(m) for m in moves),
    )


def bag_bytes(
    session_dir: str | Path, suffix: str = ".mcap", distro: str = "humble", cloud: NDArray[np.float64] | None = None
) -> tuple[bytes, BagExport]:
    """The bytes of :func:`export_bag`'s file (written to a temporary folder and removed), and its summary."""
    with tempfile.TemporaryDirectory(prefix="nbv-bag-") as tmp:
        done = export_bag(session_dir, Path(tmp) / f"scan{suffix}", distro, cloud)
        return done.path.read_bytes(), done
