"""Intel RealSense depth camera (``pyrealsense2``, extra ``[realsense]``), live or playing a recording.

The depth stream runs at the configured resolution and rate; the depth scale (metres per z16 unit) is
read from the device's depth sensor and the pinhole intrinsics from the stream profile, never typed
in. librealsense puts pixel centres at integer coordinates like OpenCV and like
:class:`planner.types.DepthFrame`, so ``ppx``/``ppy`` are ``cx``/``cy`` as they are. Depth streams of
D400 cameras are rectified (distortion coefficients all zero); a stream with distortion is refused.

A capture optionally runs librealsense post-processing filters by name (``spatial``, ``temporal``,
``hole_filling``: they keep the resolution) and averages several frames: each pixel is the mean of the
frames that had a return there (0 if none had). A frame that does not arrive within ``timeout_s`` is a
:class:`devices.protocols.CaptureError`.

``playback`` names a recording (``.bag``, or rosbag2 ``.db3`` as librealsense 2.59 writes) played back not
in real time, frame by frame: how the driver is tested offline, and how a recorded scan is replayed
through the exact code path of the live camera.

While the cell moves with move capture on, :meth:`RealSenseCamera.stream` reads the depth stream in a thread of
its own and hands every frame with its timestamp to the cell's :class:`devices.movestream.MoveStreamer`: in the
global time domain (a live camera's is turned on at opening: the device clock mapped onto the host clock) or the
system time domain (the host's arrival time), milliseconds since the epoch, the host clock the joint states are
stamped with; a frame on the camera's hardware clock cannot be placed (dropped as ``clock``). The ``temporal``
filter is not applied to moving frames (it would blend frames taken from different poses).
"""

from __future__ import annotations

import contextlib
import threading
import time
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import NDArray

from devices.drivers.common import import_vendor
from devices.movestream import FrameQueue, StampedFrame
from devices.protocols import CaptureError, DeviceError
from planner.types import DepthFrame, Intrinsics, Pose
from planner.validate import finite, integer, require

FILTERS = ("spatial", "temporal", "hole_filling")
"""Post-processing filters a config may name, applied in the order given."""


@dataclass(frozen=True)
class RealSenseConfig:
    """``[devices.camera] driver = "realsense"``."""

    width: int = 640
    """Depth image width, pixels (a mode the camera supports, e.g. 640, 848, 1280)."""
    height: int = 480
    """Depth image height, pixels."""
    fps: int = 30
    """Depth frame rate, frames per second."""
    serial: str = ""
    """Serial number of the camera to open; empty: the first one found."""
    playback: str = ""
    """A recording (.bag / .db3) to play back instead of a live camera; empty: live."""
    filters: tuple[str, ...] = ()
    """Post-processing filters by name, in order: any of "spatial", "temporal", "hole_filling"."""
    average: int = 1
    """Frames averaged per capture (each pixel: the mean of the frames with a return there)."""
    timeout_s: float = 2.0
    """Longest wait for one frame, seconds; longer is a CaptureError."""
    settle_frames: int = 5
    """Live camera: frames dropped before each capture, so the image is taken after the arm stopped."""
    min_depth: float = 0.1
    """Returns nearer than this are dropped (depth 0), metres."""
    max_depth: float = 1.5
    """Returns farther than this are dropped (depth 0), metres."""
    move_capture_gap_s: float = 0.1
    """Move capture: two joint states further apart than this place no frame between them (it is dropped), seconds."""
    move_capture_wait_s: float = 0.3
    """Move capture: how long a frame may wait for the joint state after its stamp, and frames stamped within a move
    may still arrive after it ended, seconds."""
    noise_model: str = "ideal"
    """The depth noise the planner assumes for this camera: a sensor model of ``nbv scan --sensor`` (e.g.
    "realsense-d435", "realsense-d405"). It sets the planner's plate band, ICP gate and the real sensors' candidate
    settings (``devices.planner_noise.planner_config_for``) as for that simulated sensor; the images are the
    camera's own. "ideal": the planner assumes a perfect sensor (the paper's fixed thresholds)."""

    def __post_init__(self) -> None:
        from devices.sensors import SENSORS

        p = "devices.camera."
        require(
            isinstance(self.noise_model, str) and self.noise_model in SENSORS,
            f"{p}noise_model: one of {', '.join(SENSORS)}, got {self.noise_model!r}",
        )
        for name in ("width", "height", "fps", "average"):
            v = getattr(self, name)
            require(integer(v) and v >= 1, f"{p}{name}: must be an integer >= 1, got {v!r}")
        require(
            integer(self.settle_frames) and self.settle_frames >= 0,
            f"{p}settle_frames: must be an integer >= 0, got {self.settle_frames!r}",
        )
        require(isinstance(self.serial, str), f"{p}serial: must be a string, got {self.serial!r}")
        require(isinstance(self.playback, str), f"{p}playback: must be a file path, got {self.playback!r}")
        filters = self.filters
        require(
            isinstance(filters, list | tuple) and all(isinstance(f, str) for f in filters),
            f"{p}filters: must be a list of names, got {filters!r}",
        )
        for f in filters:
            require(f in FILTERS, f"{p}filters: unknown filter {f!r} (known: {', '.join(FILTERS)})")
        object.__setattr__(self, "filters", tuple(filters))
        for name in ("timeout_s", "move_capture_gap_s", "move_capture_wait_s"):
            v = getattr(self, name)
            require(finite(v) and v > 0, f"{p}{name}: must be > 0, got {v!r}")
        require(finite(self.min_depth) and self.min_depth >= 0, f"{p}min_depth: must be >= 0, got {self.min_depth!r}")
        require(
            finite(self.max_depth) and self.max_depth > self.min_depth,
            f"{p}max_depth: must be > min_depth ({self.min_depth!r}), got {self.max_depth!r}",
        )


class RealSenseCamera:
    """A RealSense depth camera behind the :class:`devices.protocols.Camera` protocol.

    Opening starts the pipeline (DeviceError when there is no camera, the recording is missing or has
    no depth stream at the configured resolution). ``T_world_camera`` of a capture is the identity:
    the cell puts the pose from the arm and the turntable. Call :meth:`close` (or use ``with``) to stop.
    """

    def __init__(self, config: RealSenseConfig | None = None) -> None:
        self.config = config if config is not None else RealSenseConfig()
        self._rs: Any = import_vendor("pyrealsense2", "realsense", "RealSense camera")
        self.captures = 0
        self._pipeline: Any = None
        self._stream_thread: threading.Thread | None = None
        self._stream_frames: FrameQueue | None = None
        self._open()

    # ------------------------------------------------------------------ opening

    def _open(self) -> None:
        rs, cfg = self._rs, self.config
        pipeline = rs.pipeline()
        rs_config = rs.config()
        if cfg.playback:
            path = Path(cfg.playback)
            if not path.is_file():
                raise DeviceError(f"RealSense: playback file {cfg.playback!r} not found")
            rs_config.enable_device_from_file(str(path), repeat_playback=False)
        elif cfg.serial:
            rs_config.enable_device(cfg.serial)
        rs_config.enable_stream(rs.stream.depth, cfg.width, cfg.height, rs.format.z16, cfg.fps)
        source = f"recording {Path(cfg.playback).name!r}" if cfg.playback else f"camera {cfg.serial or '(first)'}"
        try:
            if cfg.playback:
                # Not real time from the first frame: resolving loads the playback device, which the
                # pipeline then reuses; set after start, frames already played in real time are lost.
                resolved = rs_config.resolve(rs.pipeline_wrapper(pipeline))
                resolved.get_device().as_playback().set_real_time(False)
            profile = pipeline.start(rs_config)
        except RuntimeError as exc:
            raise DeviceError(
                f"RealSense: cannot start a {cfg.width}x{cfg.height} z16 depth stream at {cfg.fps} fps "
                f"from {source} ({exc})"
            ) from None
        self._pipeline = pipeline
        try:
            device = profile.get_device()
            self.depth_scale = float(device.first_depth_sensor().get_depth_scale())
            stream = profile.get_stream(rs.stream.depth).as_video_stream_profile()
            k = stream.get_intrinsics()
            if any(abs(c) > 0 for c in k.coeffs):
                raise DeviceError(f"RealSense: the depth stream has lens distortion {list(k.coeffs)} (not supported)")
            self._intrinsics = Intrinsics(int(k.width), int(k.height), float(k.fx), float(k.fy), k.ppx, k.ppy)
            self.serial = str(device.get_info(rs.camera_info.serial_number))
            self.name = str(device.get_info(rs.camera_info.name))
        except BaseException:
            self.close()
            raise
        makers = {"spatial": rs.spatial_filter, "temporal": rs.temporal_filter, "hole_filling": rs.hole_filling_filter}
        self._filters = [makers[name]() for name in cfg.filters]
        self._moving_filters = [f for name, f in zip(cfg.filters, self._filters, strict=True) if name != "temporal"]
        if not cfg.playback:  # stamps on the host clock, for frames taken during a move
            with contextlib.suppress(RuntimeError, AttributeError):
                sensor = device.first_depth_sensor()
                if sensor.supports(rs.option.global_time_enabled):
                    sensor.set_option(rs.option.global_time_enabled, 1)

    def close(self) -> None:
        """Stop the pipeline (harmless when already stopped). Nothing of ours holds a frame of the device when it
        stops: the stream's reader has ended, and the filters (which keep frames they processed) are dropped."""
        self._end_stream()
        self._filters, self._moving_filters = [], []
        if self._pipeline is not None:
            pipeline, self._pipeline = self._pipeline, None
            with contextlib.suppress(RuntimeError):
                if self.config.playback:
                    self._drain(pipeline)
                pipeline.stop()

    def _drain(self, pipeline: Any) -> None:
        """Read a playback to its end, and past the playback's own stop there, before stopping the pipeline.

        librealsense 2.59 aborts now and then ("pure virtual method called") when a pipeline is stopped while its
        non-real-time playback still has frames to hand over (librealsense#3126 is the same race as a hang). At the
        end of the recording the playback's reader thread stops itself (``playback_device::stop_internal``): it
        marks the playback stopped first, so ``current_status()`` says ``stopped`` while the thread still resets the
        file reader and raises the status change the pipeline subscribed to (``pipeline.stop()`` unsubscribes and
        the pipeline is freed right after). So one more wait for frames follows the first ``stopped`` seen (each
        frame set dropped at once). (A status-changed callback of ours would say when that stop is done, but a
        Python callback called from librealsense's thread is one more hazard: 1 abort in 355 cycles with it,
        ``benchmarks/crash_realsense_stop.py``.)"""
        rs = self._rs
        playback = pipeline.get_active_profile().get_device().as_playback()
        deadline = time.monotonic() + 10.0 + self.config.timeout_s
        while playback.current_status() != rs.playback_status.stopped and time.monotonic() < deadline:
            pipeline.try_wait_for_frames(100)
        pipeline.try_wait_for_frames(100)  # the reader thread's own stop finishes meanwhile

    def __enter__(self) -> RealSenseCamera:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    # ------------------------------------------------------------------ Camera protocol

    @property
    def intrinsics(self) -> Intrinsics:
        return self._intrinsics

    def _next_depth(self) -> NDArray[np.float32]:
        """(H, W) float32 metres of the next frame, after the filters. CaptureError on timeout."""
        self._end_stream()
        if self._pipeline is None:
            raise CaptureError("RealSense: the camera is closed")
        timeout_ms = max(1, round(self.config.timeout_s * 1000))
        try:
            frames = self._pipeline.wait_for_frames(timeout_ms)
        except RuntimeError as exc:
            raise CaptureError(f"RealSense: no depth frame within {self.config.timeout_s:g} s ({exc})") from None
        depth = frames.get_depth_frame()
        if not depth:
            raise CaptureError("RealSense: a frame set without a depth frame")
        for f in self._filters:
            depth = f.process(depth)
        raw = np.asanyarray(depth.get_data())
        k = self._intrinsics
        if raw.shape != (k.height, k.width):
            raise CaptureError(f"RealSense: depth image {raw.shape}, expected {(k.height, k.width)}")
        return raw.astype(np.float32) * np.float32(self.depth_scale)

    def capture(self) -> DepthFrame:
        """The mean of ``average`` depth images (after ``settle_frames`` dropped, live only); 0 = no return.

        Returns a DepthFrame with (height, width) float32 planar z-depth in metres and the identity pose.
        """
        cfg = self.config
        if not cfg.playback:
            for _ in range(cfg.settle_frames):
                self._next_depth()
        k = self._intrinsics
        total = np.zeros((k.height, k.width), dtype=np.float64)
        count = np.zeros((k.height, k.width), dtype=np.int64)
        for _ in range(cfg.average):
            depth = self._next_depth()
            valid = depth > 0
            total[valid] += depth[valid]
            count += valid
        mean = np.divide(total, count, out=np.zeros_like(total), where=count > 0)
        in_range = (mean >= cfg.min_depth) & (mean <= cfg.max_depth)
        self.captures += 1
        return DepthFrame(np.where(in_range, mean, 0.0).astype(np.float32), Pose.identity(), k)

    # ------------------------------------------------------------------ move capture

    def stream(self) -> FrameQueue:
        """Read every new depth frame, with its timestamp in seconds on the host clock, into a fresh queue until it is
        closed (:class:`devices.movestream.FrameStreamer`; see the module docstring). CaptureError when closed."""
        if self._pipeline is None:
            raise CaptureError("RealSense: the camera is closed")
        self._end_stream()
        frames = FrameQueue()
        thread = threading.Thread(target=self._stream_into, args=(frames,), name="realsense-stream", daemon=True)
        self._stream_thread, self._stream_frames = thread, frames
        thread.start()
        return frames

    def _end_stream(self) -> None:
        """End a stream (close its queue) and wait for its reader to let go of the pipeline (a capture or a close
        comes after it)."""
        thread, self._stream_thread = self._stream_thread, None
        frames, self._stream_frames = self._stream_frames, None
        if frames is not None:
            frames.close()
        if thread is not None and thread is not threading.current_thread():
            thread.join(timeout=1.0 + self.config.timeout_s)

    def _stream_into(self, frames: FrameQueue) -> None:
        rs, k, cfg = self._rs, self._intrinsics, self.config
        clocks = (rs.timestamp_domain.global_time, rs.timestamp_domain.system_time)
        while not frames.closed and self._pipeline is not None:
            try:
                ok, got = self._pipeline.try_wait_for_frames(100)
            except RuntimeError:
                return
            if not ok:
                continue
            depth = got.get_depth_frame()
            if not depth:
                continue
            arrival = time.monotonic()
            domain = depth.get_frame_timestamp_domain()
            stamp = depth.get_timestamp() / 1000.0 if domain in clocks else None
            for f in self._moving_filters:
                depth = f.process(depth)
            raw = np.array(depth.get_data(), dtype=np.uint16, copy=True)  # the frame goes back to librealsense

            def decode(raw: NDArray[np.uint16] = raw) -> DepthFrame:
                if raw.shape != (k.height, k.width):
                    raise CaptureError(f"RealSense: depth image {raw.shape}, expected {(k.height, k.width)}")
                metres = raw.astype(np.float32) * np.float32(self.depth_scale)
                metres[(metres < cfg.min_depth) | (metres > cfg.max_depth)] = 0.0
                return DepthFrame(metres, Pose.identity(), k)

            reason = "" if stamp is not None else f"timestamp domain {domain}, not the host clock"
            frames.put(StampedFrame(stamp, decode, arrival, reason))

    def describe(self) -> str:
        """One line for ``nbv devices check``: model, serial, stream, depth scale."""
        k = self._intrinsics
        return (
            f"{self.name} #{self.serial}, depth {k.width}x{k.height} @ {self.config.fps} fps, "
            f"scale {self.depth_scale * 1000:.4g} mm, fx {k.fx:.1f} fy {k.fy:.1f}"
        )
