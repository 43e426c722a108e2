"""Write depth images into a RealSense recording with librealsense's own ``software_device`` + ``recorder``.

The file is what a real camera's recording looks like to :class:`devices.drivers.realsense.RealSenseCamera`
(``playback = "..."``): a depth sensor with a z16 stream, its depth units and intrinsics. This is how the
driver is tested without a camera (images rendered by :class:`devices.sim.SimulatedCamera`), and how a
simulated scan becomes a recording to rehearse the RealSense path of the workbench.

librealsense 2.59 (the tested version) writes rosbag2: the path must end in ``.db3``; older versions wrote ``.bag``.
"""

from __future__ import annotations

import time
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import NDArray

from devices.drivers.common import import_vendor
from planner.types import Intrinsics

Z16_MAX = 65535


def write_depth_recording(
    path: str | Path,
    depths: Sequence[NDArray[np.float32]],
    intrinsics: Intrinsics,
    *,
    depth_unit: float = 1e-4,
    fps: int = 30,
    timestamps_ms: Sequence[float] | None = None,
    domains: Sequence[str] | None = None,
) -> Path:
    """Record ``depths`` (each (H, W) float32 metres, 0 = no return) as z16 frames of one depth stream.

    depth_unit: metres per z16 count (the device's depth scale; 1e-4 keeps 0.1 mm up to 6.5 m).
    timestamps_ms: each frame's timestamp, milliseconds (None: ``i * 1000 / fps``); domains: each frame's timestamp
    domain, "system_time" (None: all), "global_time" (the host clock, as a live camera's global time) or
    "hardware_clock" (the camera's own clock): how a move's frames are recorded with their stamps.
    Depths beyond the z16 range raise ValueError. Returns the path written.
    """
    rs: Any = import_vendor("pyrealsense2", "realsense", "RealSense recording")
    path = Path(path)
    k = intrinsics
    if not depths:
        raise ValueError("depths: need at least one image")
    if not (np.isfinite(depth_unit) and depth_unit > 0):
        raise ValueError(f"depth_unit: must be > 0, got {depth_unit!r}")
    raws = []
    for i, depth in enumerate(depths):
        d = np.asarray(depth, dtype=np.float64)
        if d.shape != (k.height, k.width):
            raise ValueError(f"depths[{i}]: shape {d.shape}, expected {(k.height, k.width)}")
        if not np.all(np.isfinite(d)) or np.any(d < 0):
            raise ValueError(f"depths[{i}]: depths must be finite and >= 0")
        counts = np.rint(d / depth_unit)
        if counts.max() > Z16_MAX:
            raise ValueError(f"depths[{i}]: {d.max():.3f} m exceeds the z16 range at depth_unit {depth_unit:g}")
        raws.append(np.ascontiguousarray(counts.astype(np.uint16)))
    stamps = (
        [i * 1000.0 / fps for i in range(len(raws))] if timestamps_ms is None else [float(t) for t in timestamps_ms]
    )
    names = ["system_time"] * len(raws) if domains is None else list(domains)
    if len(stamps) != len(raws) or len(names) != len(raws):
        raise ValueError(f"timestamps_ms, domains: one per depth image ({len(raws)})")
    if not all(np.isfinite(stamps)):
        raise ValueError("timestamps_ms: must be finite")
    known = ("system_time", "global_time", "hardware_clock")
    if any(n not in known for n in names):
        raise ValueError(f"domains: each one of {', '.join(known)}, got {names}")

    if path.exists():
        path.unlink()
    device = rs.software_device()
    sensor = device.add_sensor("Depth")
    rs_k = rs.intrinsics()
    rs_k.width, rs_k.height = k.width, k.height
    rs_k.fx, rs_k.fy, rs_k.ppx, rs_k.ppy = k.fx, k.fy, k.cx, k.cy
    rs_k.model = rs.distortion.none
    rs_k.coeffs = [0.0] * 5
    stream = rs.video_stream()
    stream.type, stream.index, stream.uid = rs.stream.depth, 0, 0
    stream.width, stream.height, stream.fps, stream.bpp = k.width, k.height, fps, 2
    stream.fmt, stream.intrinsics = rs.format.z16, rs_k
    profile = sensor.add_video_stream(stream).as_video_stream_profile()
    sensor.add_read_only_option(rs.option.depth_units, float(depth_unit))
    device.register_info(rs.camera_info.name, "software depth camera (recorded)")
    device.register_info(rs.camera_info.serial_number, "000000000000")
    recorder = rs.recorder(str(path), device)
    sensor.open(profile)
    queue = rs.frame_queue(len(raws) + 1)
    sensor.start(queue)
    for i, raw in enumerate(raws):
        frame = rs.software_video_frame()
        frame.pixels = raw
        frame.bpp, frame.stride = 2, 2 * k.width
        frame.timestamp = stamps[i]
        frame.domain = getattr(rs.timestamp_domain, names[i])
        frame.frame_number = i + 1
        frame.profile = profile
        frame.depth_units = float(depth_unit)
        sensor.on_video_frame(frame)
    for _ in range(len(raws)):  # every frame has passed the recorder once it reaches the queue
        queue.wait_for_frame(5000)
    time.sleep(0.05)
    sensor.stop()
    sensor.close()
    del recorder  # the recorder writes and closes the file when it is destroyed
    return path
