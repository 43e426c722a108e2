"""A depth camera on ROS 2 topics: ``sensor_msgs/Image`` depth and ``sensor_msgs/CameraInfo`` (``realsense2_camera``
and every other vendor's camera node).

Depth encodings (REP 118): ``16UC1`` in millimetres (``depth_unit_16uc1`` scales it), ``32FC1`` in metres (NaN
and 0 = no return). The intrinsics come from the first ``CameraInfo`` (``k`` = [fx, 0, cx, 0, fy, cy, 0, 0, 1];
ROS puts pixel centres at integer coordinates like :class:`planner.types.DepthFrame`); a depth stream with
distortion is refused (a depth stream should be rectified: ``image_rect_raw``). A capture takes the first complete
image stamped after the arm and the turntable last came to rest (the shared node's ``settled_stamp``), never one
taken during a move; none within ``timeout_s`` is a :class:`devices.protocols.CaptureError` naming the topic.

While the cell moves with move capture on, :meth:`Ros2Camera.stream` hands every depth image with its header stamp
to the cell's :class:`devices.movestream.MoveStreamer` (decoded only when it is delivered), which places it by the
joint states at that stamp.
"""

from __future__ import annotations

import threading
import time
from dataclasses import dataclass
from typing import Any

import numpy as np
from numpy.typing import NDArray

from devices.drivers.ros2.dds import DdsConfig, Subscription, acquire, release
from devices.movestream import FrameQueue, StampedFrame
from devices.protocols import CaptureError, DeviceError
from planner.types import DepthFrame, Intrinsics, Pose
from planner.validate import finite, require

DEPTH_ENCODINGS = ("16UC1", "32FC1", "mono16")
"""The depth encodings a capture reads (``mono16`` is 16UC1 by another name, as some drivers say)."""


@dataclass(frozen=True)
class Ros2CameraConfig(DdsConfig):
    """``[devices.camera] driver = "ros2"``: the depth and camera-info topics (defaults: ``realsense2_camera``
    4.55 and later, which puts the node under ``/camera/camera``)."""

    depth_topic: str = "/camera/camera/depth/image_rect_raw"
    """The ``sensor_msgs/Image`` depth topic (16UC1 in mm or 32FC1 in m)."""
    info_topic: str = "/camera/camera/depth/camera_info"
    """The ``sensor_msgs/CameraInfo`` topic of that image."""
    depth_unit_16uc1: float = 0.001
    """Metres per 16UC1 unit (0.001: millimetres, as REP 118 and realsense2_camera)."""
    timeout_s: float = 2.0
    """Longest wait for camera info at start and for an image after the arm settled, seconds."""
    min_depth: float = 0.1
    """Returns nearer than this are dropped (depth 0), metres."""
    max_depth: float = 1.5
    """Returns farther than this are dropped (depth 0), metres."""
    noise_model: str = "ideal"
    """The depth noise the planner assumes for this camera (as ``[devices.camera] driver = "realsense"``)."""
    move_capture_gap_s: float = 0.1
    """Move capture: two joint states further apart than this place no frame between them (it is dropped), seconds."""
    move_capture_wait_s: float = 0.3
    """Move capture: how long a frame may wait for the joint state after its stamp, and frames stamped within a move
    may still arrive after it ended, seconds."""

    def __post_init__(self) -> None:
        from devices.sensors import SENSORS

        p = "devices.camera."
        try:
            super().__post_init__()
        except ValueError as exc:
            raise ValueError(f"{p}{exc}") from None
        for name in ("depth_topic", "info_topic"):
            v = getattr(self, name)
            require(isinstance(v, str) and v.startswith("/"), f"{p}{name}: a ROS 2 topic name (/...), got {v!r}")
        for name in ("depth_unit_16uc1", "timeout_s", "max_depth", "move_capture_gap_s", "move_capture_wait_s"):
            v = getattr(self, name)
            require(finite(v) and v > 0, f"{p}{name}: must be > 0, got {v!r}")
        require(finite(self.min_depth) and 0 <= self.min_depth < self.max_depth, f"{p}min_depth: in [0, max_depth)")
        require(self.noise_model in SENSORS, f"{p}noise_model: one of {', '.join(SENSORS)}, got {self.noise_model!r}")

    @property
    def dds(self) -> DdsConfig:
        return DdsConfig(self.domain_id, self.interface, self.peers)


def intrinsics_of(info: Any) -> Intrinsics:
    """:class:`Intrinsics` of a ``CameraInfo``; DeviceError for a distorted or empty one."""
    k = [float(v) for v in info.k]
    if info.width == 0 or info.height == 0 or k[0] <= 0 or k[4] <= 0:
        raise DeviceError(f"camera: CameraInfo has no calibration ({info.width}x{info.height}, k = {k})")
    if any(abs(float(v)) > 1e-9 for v in info.d):
        raise DeviceError(
            f"camera: the depth stream has distortion d = {list(info.d)} ({info.distortion_model}); "
            "subscribe to a rectified depth image (image_rect_raw)"
        )
    return Intrinsics(int(info.width), int(info.height), k[0], k[4], k[2], k[5])


def depth_of(image: Any, unit_16uc1: float = 0.001) -> NDArray[np.float32]:
    """(height, width) float32 metres of a depth ``Image`` (0 = no return). CaptureError for another encoding or an
    image whose data does not fill ``step * height``."""
    enc = str(image.encoding)
    if enc not in DEPTH_ENCODINGS:
        raise CaptureError(
            f"camera: image encoding {enc!r} is not a depth encoding (one of {', '.join(DEPTH_ENCODINGS)})"
        )
    h, w, step = int(image.height), int(image.width), int(image.step)
    item = 4 if enc == "32FC1" else 2
    if step < w * item or len(image.data) != step * h:
        raise CaptureError(f"camera: incomplete {enc} image ({len(image.data)} bytes for {h} rows of {step})")
    order = ">" if image.is_bigendian else "<"
    raw = np.frombuffer(image.data, dtype=np.uint8).reshape(h, step)[:, : w * item]
    if enc == "32FC1":
        depth = raw.view(order + "f4").astype(np.float32)
        depth[~np.isfinite(depth)] = 0.0
    else:
        depth = raw.view(order + "u2").astype(np.float32) * np.float32(unit_16uc1)
    return depth


def complete(image: Any) -> bool:
    """Whether an image's data fill its rows (a torn or truncated message is skipped)."""
    return len(image.data) == int(image.step) * int(image.height) and int(image.height) > 0


class Ros2Camera:
    """A :class:`devices.protocols.Camera` on ROS 2 topics (see the module docstring). DeviceError at start when no
    CameraInfo arrives within ``timeout_s``."""

    def __init__(self, config: Ros2CameraConfig) -> None:
        from devices.drivers.ros2.messages import CameraInfo, Image

        self.config = config
        self._held = False
        self._subscriptions: list[Subscription] = []
        self._streams: list[FrameQueue] = []
        self._streams_lock = threading.Lock()
        self.node = acquire(config.dds)
        self._held = True
        try:
            self.info = Subscription(self.node, config.info_topic, CameraInfo)
            self._subscriptions.append(self.info)
            self.depth = Subscription(self.node, config.depth_topic, Image, self._on_depth)
            self._subscriptions.append(self.depth)
            info = self.info.wait(lambda m: True, config.timeout_s)
            if info is None:
                raise DeviceError(
                    f"camera: no sensor_msgs/CameraInfo on {config.info_topic} within {config.timeout_s:g} s "
                    f"(DDS domain {config.domain_id}; is the camera node running?)"
                )
            self._intrinsics = intrinsics_of(info)
        except BaseException:
            self.close()
            raise

    @property
    def intrinsics(self) -> Intrinsics:
        return self._intrinsics

    def capture(self) -> DepthFrame:
        """The first complete depth image stamped after the devices last settled, as a DepthFrame (identity pose)."""
        from devices.drivers.ros2.messages import seconds_of

        after = self.node.settled_stamp
        image = self.depth.wait(lambda m: seconds_of(m.header.stamp) > after and complete(m), self.config.timeout_s)
        if image is None:
            last = self.depth.latest
            seen = (
                "none arrived"
                if last is None
                else f"the last one is stamped {seconds_of(last.header.stamp):.3f} s ({self.depth.count} received)"
            )
            raise CaptureError(
                f"camera: no complete depth image on {self.config.depth_topic} stamped after the devices settled "
                f"(at {after:.3f} s) within {self.config.timeout_s:g} s; {seen}"
            )
        return self._frame_of(image)

    def _frame_of(self, image: Any) -> DepthFrame:
        """The DepthFrame (identity pose, depth range applied) of a depth image; CaptureError for a wrong size or
        encoding."""
        k = self._intrinsics
        if (int(image.width), int(image.height)) != (k.width, k.height):
            raise CaptureError(
                f"camera: depth image {image.width}x{image.height} does not match its CameraInfo {k.width}x{k.height}"
            )
        if not complete(image):
            raise CaptureError(f"camera: incomplete depth image ({len(image.data)} bytes)")
        depth = depth_of(image, self.config.depth_unit_16uc1)
        depth[(depth < self.config.min_depth) | (depth > self.config.max_depth)] = 0.0
        return DepthFrame(depth, Pose.identity(), k)

    def stream(self) -> FrameQueue:
        """Hand every depth image from now on, with its header stamp (ROS time, seconds), to a fresh queue until it
        is closed (:class:`devices.movestream.FrameStreamer`)."""
        frames = FrameQueue(on_close=self._unstream)
        with self._streams_lock:
            self._streams.append(frames)
        return frames

    def _unstream(self, frames: FrameQueue) -> None:
        with self._streams_lock:
            if frames in self._streams:
                self._streams.remove(frames)

    def _on_depth(self, image: Any) -> None:
        """Every depth image (the reader's thread): to the open streams, if any."""
        if not self._streams:
            return
        from devices.drivers.ros2.messages import seconds_of

        frame = StampedFrame(seconds_of(image.header.stamp), lambda: self._frame_of(image), time.monotonic())
        with self._streams_lock:
            streams = list(self._streams)
        for frames in streams:
            frames.put(frame)

    def describe(self) -> str:
        k = self._intrinsics
        return f"ROS 2 camera {self.config.depth_topic} ({k.width}x{k.height}, fx {k.fx:.1f})"

    def close(self) -> None:
        """Delete this device's readers, then release its share of the DDS participant (idempotent)."""
        for subscription in self._subscriptions:
            subscription.close()
        if self._held:
            self._held = False
            release(self.node)
