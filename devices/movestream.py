"""Frames a real cell takes while it moves: each depth frame placed by the joint states at its stamp.

A camera that streams (:class:`FrameStreamer`: the ``ros2`` camera's depth topic, the RealSense's frame stream)
hands over every depth frame with its stamp; the arm and the turntable keep a history of their stamped joint
states during the move (:class:`StampedSeries`; the ``ros2`` drivers record their ``JointState`` header stamps,
other drivers are polled and stamped with the host clock, :class:`PolledSeries`). :class:`MoveStreamer` (a thread
of its own) turns them into posed frames:

- **The pose rule.** A frame stamped ``s`` gets the arm's joints and the plate's angle linearly interpolated
  between the two joint states that bracket ``s``, then ``T_table_camera = T_table_base(plate) @ FK(joints)``:
  a frame between two joint states gets the pose between. The frame waits (at most ``wait_s``) for the joint
  state after its stamp to arrive.
- **Dropped, never guessed** (each counted by its reason in :class:`MoveStreamStats`): ``before_history`` (stamped
  before the first joint state of the move), ``after_history`` (no joint state after its stamp arrived within
  ``wait_s``), ``gap`` (the two joint states around it are more than ``max_gap_s`` apart), ``clock`` (the camera
  could not stamp it on the joint states' clock), ``out_of_order`` (stamped before a frame already handled),
  ``decode`` (an image that cannot be read), ``queue_full`` (the camera delivered faster than they were placed).
- **The rate.** Of the placed frames, the one nearest each tick ``t0 + k / hz`` (k = 1, 2, ..., strictly before
  the move's end, as :func:`devices.move_capture.capture_times`) is delivered, each frame at most once, in stamp
  order; the others are ``skipped``.
- **Delivery.** ``deliver(frame, t)`` runs in the streamer's thread, during the move, with ``t`` the stamp in
  seconds since the move started (``t0``, the stamp of the last joint state before the move). A fault in it is
  counted (``failed``) and logged; it never reaches the move. :meth:`MoveStreamer.stop` (a halt) ends delivery at
  once; :meth:`MoveStreamer.finish` after the move delivers the frames stamped up to the move's end (waiting at
  most ``wait_s`` for them to arrive). The move's end is the last joint state when the move returned, marked on
  the joints' history first (:meth:`StampedSeries.end_move`: the readings go on after it): a frame stamped after
  it is ``after_move`` even when the streamer reaches it before :meth:`MoveStreamer.finish` is called.

Stamps are seconds on the joint states' clock (ROS time, or the host's ``time.time()``): the camera and the arm
must stamp with the same clock (one machine, or machines synchronised by NTP/PTP).
"""

from __future__ import annotations

import logging
import math
import queue
import threading
import time
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Protocol, runtime_checkable

import numpy as np
from numpy.typing import NDArray

from planner.types import DepthFrame, Pose
from planner.validate import finite, require

log = logging.getLogger(__name__)

DROP_REASONS = (
    "before_history",
    "after_history",
    "gap",
    "clock",
    "out_of_order",
    "decode",
    "queue_full",
)
"""Why a frame taken during a move was not placed (see the module docstring)."""


@dataclass(frozen=True)
class MoveStreamLimits:
    """How a streamed frame is placed: the joint-state gap it may fall in and how long it may wait."""

    max_gap_s: float = 0.1
    """Two joint states further apart than this do not place a frame between them (``gap``), seconds."""
    wait_s: float = 0.3
    """How long a frame waits for the joint state after its stamp, and how long after the move's end the frames
    stamped within it may still arrive, seconds."""

    def __post_init__(self) -> None:
        for name in ("max_gap_s", "wait_s"):
            v = getattr(self, name)
            require(finite(v) and v > 0, f"{name}: must be > 0, got {v!r}")


@dataclass(frozen=True)
class StampedFrame:
    """A depth frame as a streaming camera hands it over.

    stamp: seconds on the joint states' clock (None: the camera could not stamp it so; ``reason`` says why).
    decode: the frame (identity pose), read only when it is delivered; raises on a bad image.
    arrival: ``time.monotonic()`` when it arrived.
    """

    stamp: float | None
    decode: Callable[[], DepthFrame]
    arrival: float
    reason: str = ""


class FrameQueue:
    """The frames a camera streams to one consumer (bounded: a full queue drops and counts the frame)."""

    def __init__(self, maxsize: int = 64, on_close: Callable[[FrameQueue], None] | None = None) -> None:
        self._queue: queue.Queue[StampedFrame] = queue.Queue(maxsize)
        self._on_close = on_close
        self.overflow = 0
        self.closed = False

    def put(self, frame: StampedFrame) -> None:
        """Called by the camera's thread for every frame (never blocks)."""
        if self.closed:
            return
        try:
            self._queue.put_nowait(frame)
        except queue.Full:
            self.overflow += 1

    def get(self, timeout: float) -> StampedFrame | None:
        """The next frame, or None after ``timeout`` seconds."""
        try:
            return self._queue.get(timeout=timeout)
        except queue.Empty:
            return None

    def close(self) -> None:
        """The camera stops handing frames to this queue (idempotent)."""
        if not self.closed:
            self.closed = True
            if self._on_close is not None:
                self._on_close(self)


@runtime_checkable
class FrameStreamer(Protocol):
    """A camera that streams stamped depth frames (while the cell moves)."""

    def stream(self) -> FrameQueue:
        """Start handing every new frame to a fresh queue (until the queue is closed)."""
        ...


@runtime_checkable
class JointRecorder(Protocol):
    """An arm whose driver receives stamped joint states (the ``ros2`` arm)."""

    def record_joints(self) -> StampedSeries:
        """A history of the joint states, from the latest one on, until :meth:`stop_recording`."""
        ...

    def stop_recording(self, series: StampedSeries) -> None: ...


@runtime_checkable
class PlateRecorder(Protocol):
    """A turntable whose driver receives stamped joint states (the ``ros2`` turntable)."""

    def record_plate(self) -> StampedSeries:
        """A history of the plate angle (radians), from the latest joint state on, until :meth:`stop_recording`."""
        ...

    def stop_recording(self, series: StampedSeries) -> None: ...


class StampedSeries:
    """Stamped values (an arm's joints (n,), a plate's angle) in stamp order, interpolated at a stamp.

    Thread-safe: the driver's thread :meth:`add` s while the streamer reads. A value stamped before the last one
    is ignored (counted in ``out_of_order``). ``angle``: the values are angles (radians) that may wrap at pi (a
    polled plate angle): the interpolation takes the short way round. A value added with ``rest`` (a device that
    reports only while it moves, seen standing still) holds until the next value: no gap limit after it, and it
    covers every later stamp while it is the last.

    :meth:`end_move` marks the move's end at the last value (the driver goes on adding after it): a value that was
    here before the mark is stamped at or before the move's end, so a frame placed by it is a frame of the move.
    """

    def __init__(self, angle: bool = False) -> None:
        self._stamps: list[float] = []
        self._values: list[NDArray[np.float64]] = []
        self._rest: list[bool] = []
        self._angle = angle
        self._cond = threading.Condition()
        self._end: float | None = None
        self.out_of_order = 0

    def add(self, stamp: float, value: NDArray[np.float64] | float, rest: bool = False) -> None:
        v = np.atleast_1d(np.asarray(value, dtype=np.float64)).copy()
        with self._cond:
            if self._stamps and stamp <= self._stamps[-1]:
                if stamp < self._stamps[-1]:
                    self.out_of_order += 1
                return
            self._stamps.append(float(stamp))
            self._values.append(v)
            self._rest.append(bool(rest))
            self._cond.notify_all()

    def __len__(self) -> int:
        with self._cond:
            return len(self._stamps)

    @property
    def first_stamp(self) -> float | None:
        with self._cond:
            return self._stamps[0] if self._stamps else None

    @property
    def last_stamp(self) -> float | None:
        with self._cond:
            return self._stamps[-1] if self._stamps else None

    def end_move(self) -> float | None:
        """The move ended now: its end is the stamp of the last value (None: no value); returns it. Values added
        later are not of the move (:attr:`end`)."""
        with self._cond:
            if self._end is None and self._stamps:
                self._end = self._stamps[-1]
            return self._end

    @property
    def end(self) -> float | None:
        """The move's end marked by :meth:`end_move` (None: not yet, the move goes on)."""
        with self._cond:
            return self._end

    def wait_past(self, stamp: float, timeout: float) -> bool:
        """Whether a value stamped at or after ``stamp`` is here, or the last one rests (waiting at most ``timeout``
        seconds for either)."""
        deadline = time.monotonic() + timeout
        with self._cond:
            while not self._stamps or (self._stamps[-1] < stamp and not self._rest[-1]):
                left = deadline - time.monotonic()
                if left <= 0:
                    return False
                self._cond.wait(left)
            return True

    def snapshot(self) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
        """((K,) stamps, (K, n) values) so far."""
        with self._cond:
            if not self._stamps:
                return np.zeros(0), np.zeros((0, 0))
            return np.array(self._stamps), np.stack(self._values)

    def at(self, stamp: float, max_gap_s: float) -> tuple[NDArray[np.float64] | None, str]:
        """((n,) the value interpolated at ``stamp``, "") or (None, the reason: ``before_history``,
        ``after_history``, ``gap``)."""
        with self._cond:
            stamps = self._stamps
            if not stamps or stamp < stamps[0]:
                return None, "before_history"
            if stamp > stamps[-1]:
                return (self._values[-1].copy(), "") if self._rest[-1] else (None, "after_history")
            i = int(np.searchsorted(stamps, stamp, side="left"))
            if stamps[i] == stamp:
                return self._values[i].copy(), ""
            s0, s1 = stamps[i - 1], stamps[i]
            a, b = self._values[i - 1], self._values[i]
            resting = self._rest[i - 1] and self._rest[i] and bool(np.array_equal(a, b))
        if resting:
            return a.copy(), ""
        if s1 - s0 > max_gap_s:
            return None, "gap"
        w = (stamp - s0) / (s1 - s0)
        step = b - a
        if self._angle:
            step = (step + math.pi) % (2 * math.pi) - math.pi
        return a + w * step, ""


class PolledSeries:
    """A :class:`StampedSeries` of a driver without stamped states: ``read()`` polled at ``hz`` in a thread of its
    own, each value stamped with the host clock (``time.time()``, the RealSense's global time domain) when it was
    read. A failed read is skipped (the gap rule then drops the frames it would have placed)."""

    def __init__(self, read: Callable[[], NDArray[np.float64] | float], hz: float = 200.0, angle: bool = False) -> None:
        require(finite(hz) and hz > 0, f"hz: must be > 0, got {hz!r}")
        self.series = StampedSeries(angle=angle)
        self._read = read
        self._period = 1.0 / hz
        self._stop = threading.Event()
        self._poll()
        self._thread = threading.Thread(target=self._run, name="joint-poll", daemon=True)
        self._thread.start()

    def _poll(self) -> None:
        try:
            value = self._read()
        except Exception:  # a silent device: no value, the gap shows it
            return
        self.series.add(time.time(), value)

    def _run(self) -> None:
        while not self._stop.wait(self._period):
            self._poll()

    def close(self) -> None:
        self._stop.set()
        self._thread.join(timeout=1.0)


@dataclass
class MoveStreamStats:
    """What the stream of one move did (``HardwareCell.last_move_stream``)."""

    hz: float
    t0: float | None = None
    """The stamp the move started at (the last joint state before it), seconds."""
    end: float | None = None
    """The stamp the move ended at (the last joint state when it returned), seconds."""
    received: int = 0
    """Frames the camera handed over during the stream."""
    placed: int = 0
    """Frames stamped within the move that got a pose."""
    delivered: int = 0
    skipped: int = 0
    """Placed frames the rate left out."""
    after_move: int = 0
    """Frames stamped after the move's end (not move frames)."""
    failed: int = 0
    """Deliveries whose callback raised."""
    dropped: dict[str, int] = field(default_factory=dict)
    """Reason -> frames (:data:`DROP_REASONS`)."""
    latency_s: list[float] = field(default_factory=list)
    """Per delivered frame: the host clock when it was delivered minus its stamp, seconds."""
    error: str = ""
    """Why the stream ended early (an internal fault, logged), or "" ."""
    halted: bool = False

    def drop(self, reason: str) -> None:
        self.dropped[reason] = self.dropped.get(reason, 0) + 1

    def summary(self) -> str:
        """One line for the log."""
        drops = ", ".join(f"{k} {v}" for k, v in sorted(self.dropped.items())) or "none"
        lat = f", latency median {np.median(self.latency_s) * 1000:.0f} ms" if self.latency_s else ""
        move = f" over {self.end - self.t0:.2f} s" if self.t0 is not None and self.end is not None else ""
        return (
            f"move capture at {self.hz:g} Hz{move}: {self.delivered} delivered of {self.received} received "
            f"({self.placed} placed, {self.skipped} skipped by the rate; dropped: {drops}; {self.failed} failed "
            f"deliveries){lat}"
        )


class MoveStreamer:
    """Places and delivers the frames of one move (see the module docstring); a thread of its own.

    frames: the camera's queue (closed when the streamer ends). joints, plate: the arm's and the plate's histories
    of this move. pose_of(q (n,), plate angle) -> ``T_table_camera``. t0: the move's start stamp. hz: the rate.
    deliver(frame with its pose, seconds since t0).
    """

    def __init__(
        self,
        frames: FrameQueue,
        joints: StampedSeries,
        plate: StampedSeries,
        pose_of: Callable[[NDArray[np.float64], float], Pose],
        t0: float,
        hz: float,
        deliver: Callable[[DepthFrame, float], None],
        limits: MoveStreamLimits | None = None,
    ) -> None:
        require(finite(hz) and hz > 0, f"hz: must be > 0, got {hz!r}")
        self.frames = frames
        self.joints = joints
        self.plate = plate
        self.pose_of = pose_of
        self.t0 = float(t0)
        self.period = 1.0 / hz
        self.deliver = deliver
        self.limits = limits if limits is not None else MoveStreamLimits()
        self.stats = MoveStreamStats(hz=float(hz), t0=self.t0)
        self._end: float | None = None
        self._finish_by: float | None = None
        self._stopped = threading.Event()
        self._tick = 1
        self._last_stamp = -math.inf
        self._pending: tuple[float, StampedFrame, Pose] | None = None  # placed, stamped at or before the next tick
        self._delivered_stamp = -math.inf
        self._thread = threading.Thread(target=self._run, name="move-stream", daemon=True)
        self._thread.start()

    # ------------------------------------------------------------------ control (the move's thread)

    def stop(self) -> None:
        """End delivery now (a halt): nothing more is delivered, the camera's queue is closed."""
        self.stats.halted = True
        self._stopped.set()
        self.frames.close()

    def finish(self, end: float | None) -> MoveStreamStats:
        """The move ended at stamp ``end`` (None: unknown, deliver nothing more): deliver the frames stamped up to it
        (waiting at most ``wait_s`` for them), then end. Returns the stats."""
        if end is None:
            self._stopped.set()
        else:
            self._end = float(end)
            self.stats.end = self._end
            self._finish_by = time.monotonic() + self.limits.wait_s
        self._thread.join(timeout=self.limits.wait_s * 3 + 5.0)
        self.frames.close()
        if self.frames.overflow:
            self.stats.dropped["queue_full"] = self.stats.dropped.get("queue_full", 0) + self.frames.overflow
        return self.stats

    # ------------------------------------------------------------------ the thread

    def _move_end(self) -> float | None:
        """The move's end as known now: given to :meth:`finish`, else marked on the joints' history
        (:meth:`StampedSeries.end_move`, before :meth:`finish` is called), else None (the move goes on).

        A frame is handled once a joint state past its stamp is here; a state that came before the end was marked
        is stamped at or before it, so a frame handled while the end is unknown is a frame of the move."""
        return self._end if self._end is not None else self.joints.end

    def _run(self) -> None:
        try:
            while not self._stopped.is_set():
                late = self._finish_by is not None and time.monotonic() > self._finish_by
                frame = self.frames.get(timeout=0.0 if late else 0.02)
                if frame is None:
                    if late:  # the move ended a while ago and nothing more has arrived
                        break
                    continue
                if self._stopped.is_set() or self._handle(frame):
                    break
            if not self._stopped.is_set():
                self._flush()
        except Exception as exc:  # a fault of the stream never reaches the move
            self.stats.error = f"{type(exc).__name__}: {exc}"
            log.exception("move capture: the stream failed (the move goes on)")
        finally:
            self.frames.close()
            st = self.stats
            st.skipped = st.placed - st.delivered - st.failed - st.dropped.get("decode", 0)

    def _handle(self, frame: StampedFrame) -> bool:
        """Place one frame; True when it is stamped after the move's end (the stream is complete)."""
        self.stats.received += 1
        if frame.stamp is None:
            self.stats.drop("clock")
            return False
        s = frame.stamp
        end = self._move_end()
        if end is not None and s > end:
            self.stats.after_move += 1
            return True
        if s < self.t0:
            self.stats.drop("before_history")
            return False
        if s <= self._last_stamp:
            self.stats.drop("out_of_order")
            return False
        self._last_stamp = s
        wait = max(0.0, self.limits.wait_s - (time.monotonic() - frame.arrival))
        self.joints.wait_past(s, wait)
        self.plate.wait_past(s, max(0.0, self.limits.wait_s - (time.monotonic() - frame.arrival)))
        end = self._move_end()
        if end is not None and s > end:  # the move ended while it waited (the joint states past it came after)
            self.stats.after_move += 1
            return True
        q, why = self.joints.at(s, self.limits.max_gap_s)
        if q is None:
            self.stats.drop(why)
            return False
        theta, why = self.plate.at(s, self.limits.max_gap_s)
        if theta is None:
            self.stats.drop(why)
            return False
        pose = self.pose_of(q, float(theta[0]))
        self.stats.placed += 1
        self._select(s, frame, pose)
        return False

    def _select(self, s: float, frame: StampedFrame, pose: Pose) -> None:
        """The rate: the placed frame nearest each tick, each at most once (``frame`` is stamped ``s``, after every
        frame before it)."""
        end = self._move_end()
        while self.t0 + self._tick * self.period <= s:
            tick = self.t0 + self._tick * self.period
            if end is not None and tick >= end:
                break
            if self._pending is not None and tick - self._pending[0] <= s - tick:
                self._send(*self._pending)  # a no-op when it went to the tick before
            else:
                self._send(s, frame, pose)
            self._tick += 1
        self._pending = (s, frame, pose)

    def _flush(self) -> None:
        """After the last frame of the move: a tick up to its end not yet served goes to the last placed frame when
        it is within one period of it."""
        if self._pending is None or self._pending[0] <= self._delivered_stamp:
            return
        tick = self.t0 + self._tick * self.period
        if self._end is not None and tick < self._end and tick - self._pending[0] <= self.period:
            self._send(*self._pending)

    def _send(self, s: float, frame: StampedFrame, pose: Pose) -> None:
        if s <= self._delivered_stamp or self._stopped.is_set():
            return
        self._delivered_stamp = s
        try:
            depth = frame.decode()
        except Exception as exc:
            self.stats.drop("decode")
            log.warning("move capture: a frame stamped %.3f cannot be read (%s)", s, exc)
            return
        try:
            self.deliver(depth.with_pose(pose), s - self.t0)
        except Exception:
            self.stats.failed += 1
            log.exception("move capture: delivering the frame stamped %.3f failed (the move goes on)", s)
            return
        self.stats.delivered += 1
        self.stats.latency_s.append(time.time() - s)
