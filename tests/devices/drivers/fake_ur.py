"""An in-process UR controller behind the exact ur_rtde methods the driver calls (same names, same signatures).

``FakeRTDEControl`` / ``FakeRTDEReceive`` stand in for ``rtde_control.RTDEControlInterface`` /
``rtde_receive.RTDEReceiveInterface``; both talk to the :class:`FakeController` registered under the host
name (``CONTROLLERS``). The controller moves the joints in real time: a ``moveJ`` path runs each segment
at the commanded speed (linear in joint space; ``time_scale`` times faster for the tests that check where the arm
goes, not how long it takes), a ``servoJ`` puts the joints at the command. Faults are
scheduled with :meth:`FakeController.inject`: at that many seconds into the next motion the joints
freeze where they are and the controller behaves like the real one (protective or emergency stop: the
safety mode changes and the control script stops; disconnect: both interfaces report the link down).
test_ur.py checks every public method here against the real classes' signatures.
"""

from __future__ import annotations

import datetime
import threading
import time
from dataclasses import dataclass, field

import numpy as np

CONTROLLERS: dict[str, FakeController] = {}


@dataclass
class FakeController:
    """One simulated UR controller (CB3-like: 125 Hz unless the interface asks for another rate)."""

    q: np.ndarray = field(default_factory=lambda: np.array([0.0, -1.57, 1.57, -1.57, -1.57, 0.0]))
    safety_mode: int = 1
    connected: bool = True
    program_running: bool = True
    connect_delay_s: float = 0.0
    start_delay_s: float = 0.0
    """An async path starts this long after moveJ returns (its progress stays negative until then)."""
    hold_after_s: float | None = None
    """The next path stops advancing this many seconds in and keeps running (progress >= 0, the joints still)
    until it is stopped: a real arm slowed down, so that a stop certainly finds its move in flight."""
    time_scale: float = 1.0
    """A ``moveJ`` path runs this many times faster than its commanded speed (1: in real time). The driver waits
    for the controller to say the path ended, so a faster fake only shortens the tests' wall time; the tests of
    move timing (move capture stamps, timeouts) keep 1."""
    calls: list[tuple] = field(default_factory=list)
    paths: list[list[tuple[float, float, np.ndarray, np.ndarray]]] = field(default_factory=list)
    """Every path it ran: its segments (start, end on the monotonic clock, joints at start, at end), kept after the
    path ends (the running path's segments are cleared when it ends)."""
    _segments: list[tuple[float, float, np.ndarray, np.ndarray]] = field(default_factory=list)
    _progress: int = -1
    _idle: int = -1  # the negative progress while no async operation runs: toggles -1 / -2 at each end
    _fault: tuple[str, float] | None = None
    _fault_at: float | None = None
    _hold_at: float | None = None
    _lock: threading.RLock = field(default_factory=threading.RLock)

    def inject(self, kind: str, after_s: float) -> None:
        """Schedule a fault ``after_s`` seconds into the next motion: "protective_stop", "emergency_stop",
        "disconnect" or "script_stopped"."""
        assert kind in ("protective_stop", "emergency_stop", "disconnect", "script_stopped")
        self._fault = (kind, after_s)

    def _arm_fault(self, now: float) -> None:
        if self._fault is not None and self._fault_at is None:
            self._fault_at = now + self._fault[1]

    def _position(self, t: float) -> np.ndarray:
        for t0, t1, q0, q1 in self._segments:
            if t <= t1:
                s = 0.0 if t1 == t0 else min(max((t - t0) / (t1 - t0), 0.0), 1.0)
                return q0 + s * (q1 - q0)
        return self._segments[-1][3]

    def update(self) -> None:
        """Advance the simulated motion to now; fire a due fault."""
        with self._lock:
            now = time.monotonic()
            if self._fault_at is not None and now >= self._fault_at:
                if self._segments:
                    self.q = self._position(self._fault_at)
                    self._finish()
                kind = self._fault[0] if self._fault else ""
                self._fault, self._fault_at = None, None
                if kind == "protective_stop":
                    self.safety_mode, self.program_running = 3, False
                elif kind == "emergency_stop":
                    self.safety_mode, self.program_running = 7, False
                elif kind == "disconnect":
                    self.connected = False
                else:
                    self.program_running = False
                return
            if self._segments:
                if self._hold_at is not None:
                    now = min(now, self._hold_at)
                self.q = self._position(now)
                ends = [t1 for _, t1, _, _ in self._segments]
                if now >= ends[-1]:
                    self._finish()
                elif now >= self._segments[0][0]:
                    self._progress = int(np.searchsorted(ends, now))

    def start_path(self, path: list[list[float]]) -> None:
        with self._lock:
            now = time.monotonic()
            self._arm_fault(now)
            if self.hold_after_s is not None:
                self._hold_at, self.hold_after_s = now + self.start_delay_s + self.hold_after_s, None
            t, q = now + self.start_delay_s, self.q.copy()
            self._segments = []
            for entry in path:
                target, speed = np.array(entry[:6]), entry[6]
                duration = float(np.max(np.abs(target - q))) / (speed * self.time_scale)
                self._segments.append((t, t + duration, q, target))
                t, q = t + duration, target
            self.paths.append(list(self._segments))
            self._progress = self._idle if self.start_delay_s else 0

    def _finish(self) -> None:
        """The async operation ended (done, stopped or aborted): its progress becomes the other negative value."""
        self._idle = -2 if self._idle == -1 else -1
        self._segments, self._progress, self._hold_at = [], self._idle, None

    @property
    def holding(self) -> bool:
        """A path held by ``hold_after_s`` has reached its hold (it runs on, the joints still, until stopped)."""
        with self._lock:
            return self._hold_at is not None and time.monotonic() >= self._hold_at

    def halt(self) -> None:
        with self._lock:
            self.update()
            if self._segments:
                self._finish()


def _controller(hostname: str) -> FakeController:
    if hostname not in CONTROLLERS:
        raise RuntimeError(f"Could not connect to {hostname}: Connection refused")
    c = CONTROLLERS[hostname]
    if c.connect_delay_s:
        time.sleep(c.connect_delay_s)
    return c


class FakeRTDEReceive:
    """``rtde_receive.RTDEReceiveInterface``: the methods the driver reads."""

    def __init__(
        self,
        hostname: str,
        frequency: float = -1.0,
        variables: list[str] = [],  # noqa: B006 - the real signature
        verbose: bool = False,
        use_upper_range_registers: bool = False,
        rt_priority: int = 0,
    ) -> None:
        self._c = _controller(hostname)

    def isConnected(self) -> bool:
        self._c.update()
        return self._c.connected

    def getActualQ(self) -> list[float]:
        self._c.update()
        return [float(v) for v in self._c.q]

    def getSafetyMode(self) -> int:
        self._c.update()
        return self._c.safety_mode

    def isProtectiveStopped(self) -> bool:
        self._c.update()
        return self._c.safety_mode == 3

    def isEmergencyStopped(self) -> bool:
        self._c.update()
        return self._c.safety_mode in (6, 7)

    def disconnect(self) -> None:
        self._c.calls.append(("receive.disconnect",))


class FakeRTDEControl:
    """``rtde_control.RTDEControlInterface``: the commands the driver sends."""

    def __init__(
        self,
        hostname: str,
        frequency: float = -1.0,
        flags: int = 1,
        ur_cap_port: int = 50002,
        rt_priority: int = 0,
    ) -> None:
        self._c = _controller(hostname)
        self._period = 1.0 / (frequency if frequency > 0 else 125.0)
        self._c.calls.append(("connect", frequency))

    def _alive(self) -> bool:
        self._c.update()
        if not self._c.connected:
            raise RuntimeError("RTDEControlInterface: RTDE connection lost")
        return self._c.program_running

    def isConnected(self) -> bool:
        self._c.update()
        return self._c.connected

    def isProgramRunning(self) -> bool:
        self._c.update()
        return self._c.connected and self._c.program_running

    def moveJ(self, path: list[list[float]], asynchronous: bool = False) -> bool:
        self._c.calls.append(("moveJ", [list(p) for p in path], asynchronous))
        if not self._alive():
            return False
        self._c.start_path(path)
        if not asynchronous:
            while self._c._segments:
                time.sleep(0.005)
                self._c.update()
        return True

    def getAsyncOperationProgress(self) -> int:
        self._c.update()
        return self._c._progress

    def stopJ(self, a: float = 2.0, asynchronous: bool = False) -> None:
        self._c.calls.append(("stopJ", a, asynchronous))
        self._c.halt()

    def servoJ(self, arg0: list[float], arg1: float, arg2: float, arg3: float, arg4: float, arg5: float) -> bool:
        self._c.calls.append(("servoJ", list(arg0), arg3, arg4, arg5))
        with self._c._lock:
            self._c._arm_fault(time.monotonic())
        if not self._alive():
            return False
        with self._c._lock:
            self._c.q = np.array(arg0, dtype=np.float64)
        return True

    def servoStop(self, a: float = 10.0) -> bool:
        self._c.calls.append(("servoStop", a))
        with self._c._lock:
            self._c._fault, self._c._fault_at = None, None  # a fault not yet due belongs to this motion
        return True

    def initPeriod(self) -> datetime.timedelta:
        start = datetime.timedelta(seconds=time.monotonic())
        self._c.calls.append(("initPeriod", start))
        return start

    def waitPeriod(self, arg0: datetime.timedelta) -> None:
        self._c.calls.append(("waitPeriod", arg0))
        rest = arg0.total_seconds() + self._period - time.monotonic()
        if rest > 0:
            time.sleep(rest)

    def stopScript(self) -> None:
        self._c.calls.append(("stopScript",))
        self._c.program_running = False

    def disconnect(self) -> None:
        self._c.calls.append(("control.disconnect",))
