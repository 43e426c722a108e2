"""Universal Robots arm over RTDE (``ur-rtde``, extra ``[ur]``) behind :class:`devices.protocols.JointArm`.

The trajectory comes from our side (kinematics, collision checks and planning in ``devices/``); this
driver only executes it, in one of two modes:

- ``path`` (default): ``moveJ`` with the trajectory's waypoints (at most ``max_waypoints``, blended by
  ``blend_m``), asynchronously, at ``speed_fraction`` / ``acceleration_fraction`` of the configured
  maximum joint speed and acceleration; the controller times the motion.
- ``servo``: ``servoJ`` at ``servo_rate_hz`` along the trajectory slowed to ``speed_fraction`` of its
  speed (``initPeriod`` / ``waitPeriod`` keep the controller's rate), then ``servoStop``.

Before anything is sent: the joint names must be the arm's, the trajectory must start within
``start_tolerance_deg`` of the arm's joints, and it must keep the joint limits (positions, and in servo
mode the scaled speeds and accelerations; :class:`devices.drivers.limits.JointLimits`). While it runs the
driver polls the controller: a protective stop, an emergency stop (or any safety mode other than normal
or reduced), the control script no longer running, a lost connection, or a motion that does not end in
time stops the arm and raises :class:`devices.drivers.common.ArmFaultError` with the controller's reason
and the last joint state read. ``stop()`` (from any thread) ends a running motion with ``stopJ`` /
``servoStop`` within one poll period.
"""

from __future__ import annotations

import contextlib
import math
import threading
import time
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any, Literal

import numpy as np
from numpy.typing import NDArray

from devices.drivers.common import ArmFaultError, import_vendor
from devices.drivers.limits import JointLimits, LimitError
from devices.protocols import DeviceError
from devices.timeout import DeviceTimeoutError, call_with_timeout
from devices.trajectory import JointTrajectory
from planner.validate import finite, integer, require

UR_JOINTS = (
    "shoulder_pan_joint",
    "shoulder_lift_joint",
    "elbow_joint",
    "wrist_1_joint",
    "wrist_2_joint",
    "wrist_3_joint",
)
"""The joint names of every UR arm (URDF / ROS names), in the controller's order."""

SAFETY_MODES = {
    1: "normal",
    2: "reduced",
    3: "protective stop",
    4: "recovery mode",
    5: "safeguard stop",
    6: "system emergency stop",
    7: "robot emergency stop",
    8: "safety violation",
    9: "safety fault",
    10: "validate joint id",
    11: "undefined safety mode",
    12: "automatic mode safeguard stop",
    13: "three-position enabling stop",
}
"""UR safety modes (``getSafetyMode``); 1 and 2 let the arm move."""


@dataclass(frozen=True)
class URConfig:
    """``[devices.arm] driver = "ur"``: where the controller is and how fast the arm may move."""

    host: str = ""
    """The controller's IP address or host name (required)."""
    connect_timeout_s: float = 5.0
    """Longest wait for each RTDE interface to connect, seconds."""
    mode: Literal["path", "servo"] = "path"
    """How a trajectory is executed: "path" (moveJ through waypoints) or "servo" (servoJ at the controller rate)."""
    speed_fraction: float = 0.25
    """Speed scale in (0, 1]: path mode moves at this fraction of max_joint_speed_deg; servo mode plays the
    trajectory this much slower (speeds x fraction, accelerations x fraction^2)."""
    acceleration_fraction: float = 0.25
    """Path mode: joint acceleration as this fraction of max_joint_acceleration_deg, in (0, 1]."""
    max_joint_speed_deg: float = 60.0
    """Limit on any joint's speed, deg/s; a servo trajectory faster than this (after scaling) is refused."""
    max_joint_acceleration_deg: float = 120.0
    """Limit on any joint's acceleration, deg/s^2 (servo mode checks the scaled trajectory against it)."""
    joint_lower_deg: tuple[float, ...] = (-360.0,) * 6
    """Lower joint position bounds, degrees (tighten them to keep cables and the camera safe)."""
    joint_upper_deg: tuple[float, ...] = (360.0,) * 6
    """Upper joint position bounds, degrees."""
    start_tolerance_deg: float = 1.0
    """A trajectory must start within this of the arm's joints (largest joint difference), degrees."""
    goal_tolerance_deg: float = 0.5
    """After a motion the arm must be within this of the trajectory's end, degrees."""
    max_waypoints: int = 20
    """Path mode: the trajectory is thinned to at most this many moveJ waypoints (first and last kept)."""
    blend_m: float = 0.0
    """Path mode: blend radius between waypoints, metres (0: stop at each waypoint)."""
    servo_rate_hz: float = 125.0
    """Servo mode: servoJ rate, Hz (125 for CB3 controllers, 500 for e-Series)."""
    lookahead_s: float = 0.1
    """Servo mode: servoJ lookahead time, seconds, in [0.03, 0.2]."""
    servo_gain: float = 300.0
    """Servo mode: servoJ proportional gain, in [100, 2000]."""
    poll_s: float = 0.02
    """How often a running path motion is checked for faults and stop requests, seconds."""
    timeout_margin_s: float = 5.0
    """A motion may take its expected duration times 1.5 plus this before it counts as hung, seconds."""

    def __post_init__(self) -> None:
        p = "devices.arm."
        require(isinstance(self.host, str) and self.host.strip() != "", f"{p}host: required (the controller's address)")
        require(self.mode in ("path", "servo"), f"{p}mode: 'path' or 'servo', got {self.mode!r}")
        for name in ("speed_fraction", "acceleration_fraction"):
            v = getattr(self, name)
            require(finite(v) and 0 < v <= 1, f"{p}{name}: must be in (0, 1], got {v!r}")
        for name in ("connect_timeout_s", "max_joint_speed_deg", "max_joint_acceleration_deg", "servo_rate_hz"):
            v = getattr(self, name)
            require(finite(v) and v > 0, f"{p}{name}: must be > 0, got {v!r}")
        for name in ("start_tolerance_deg", "goal_tolerance_deg", "poll_s", "timeout_margin_s"):
            v = getattr(self, name)
            require(finite(v) and v > 0, f"{p}{name}: must be > 0, got {v!r}")
        require(finite(self.blend_m) and self.blend_m >= 0, f"{p}blend_m: must be >= 0, got {self.blend_m!r}")
        require(
            finite(self.lookahead_s) and 0.03 <= self.lookahead_s <= 0.2,
            f"{p}lookahead_s: must be in [0.03, 0.2], got {self.lookahead_s!r}",
        )
        require(
            finite(self.servo_gain) and 100 <= self.servo_gain <= 2000,
            f"{p}servo_gain: must be in [100, 2000], got {self.servo_gain!r}",
        )
        require(
            integer(self.max_waypoints) and self.max_waypoints >= 2,
            f"{p}max_waypoints: must be an integer >= 2, got {self.max_waypoints!r}",
        )
        for name in ("joint_lower_deg", "joint_upper_deg"):
            v = getattr(self, name)
            require(
                isinstance(v, list | tuple) and len(v) == 6 and finite(*v),
                f"{p}{name}: must be 6 finite numbers (degrees), got {v!r}",
            )
            object.__setattr__(self, name, tuple(float(x) for x in v))
        bad = [UR_JOINTS[j] for j in range(6) if not self.joint_lower_deg[j] < self.joint_upper_deg[j]]
        require(not bad, f"{p}joint_upper_deg: must be above joint_lower_deg for {', '.join(bad)}")

    @property
    def limits(self) -> JointLimits:
        """The configured limits in radians."""
        return JointLimits(
            tuple(math.radians(v) for v in self.joint_lower_deg),
            tuple(math.radians(v) for v in self.joint_upper_deg),
            math.radians(self.max_joint_speed_deg),
            math.radians(self.max_joint_acceleration_deg),
        )


Factory = Callable[[str, float], Any]
"""Builds an RTDE interface from (hostname, frequency): the ur_rtde class itself, or a test double."""


class URArm:
    """A UR arm (any of UR3/5/10/16, CB3 or e-Series) executing joint trajectories over RTDE.

    control_factory / receive_factory: build the ``RTDEControlInterface`` / ``RTDEReceiveInterface``
    (default: the ``ur_rtde`` classes, imported now). Connecting raises DeviceError with the reason, or
    DeviceTimeoutError after ``connect_timeout_s``. ``last_joint_positions`` is the last state read.
    """

    def __init__(
        self,
        config: URConfig,
        *,
        control_factory: Factory | None = None,
        receive_factory: Factory | None = None,
    ) -> None:
        self.config = config
        self._limits = config.limits
        make_control: Factory = (
            control_factory
            if control_factory is not None
            else import_vendor("rtde_control", "ur", "UR arm").RTDEControlInterface
        )
        make_receive: Factory = (
            receive_factory
            if receive_factory is not None
            else import_vendor("rtde_receive", "ur", "UR arm").RTDEReceiveInterface
        )
        self.last_joint_positions: NDArray[np.float64] | None = None
        self._stop = threading.Event()
        self._moving = threading.Lock()
        host = config.host
        self._receive = self._connect(lambda: make_receive(host, -1.0), "RTDE receive")
        try:
            rate = config.servo_rate_hz if config.mode == "servo" else -1.0  # -1: the controller's own rate
            self._control = self._connect(lambda: make_control(host, rate), "RTDE control")
        except BaseException:
            self._receive.disconnect()
            raise
        self.joint_positions()

    def _connect(self, make: Callable[[], Any], what: str) -> Any:
        try:
            return call_with_timeout(make, self.config.connect_timeout_s, f"UR {self.config.host} {what}")
        except DeviceTimeoutError:
            raise
        except (RuntimeError, OSError) as exc:
            raise DeviceError(f"arm: cannot connect to UR controller {self.config.host} ({what}: {exc})") from None

    def close(self) -> None:
        """Stop the control script and disconnect both interfaces."""
        control, receive = getattr(self, "_control", None), getattr(self, "_receive", None)
        for iface in (control, receive):
            if iface is not None:
                with contextlib.suppress(RuntimeError):
                    if iface is control:
                        iface.stopScript()
                    iface.disconnect()

    # ------------------------------------------------------------------ state

    @property
    def joint_names(self) -> tuple[str, ...]:
        return UR_JOINTS

    def joint_positions(self) -> NDArray[np.float64]:
        """(6,) the actual joint positions, radians. ArmFaultError if the connection is lost."""
        if not self._receive.isConnected():
            raise ArmFaultError("lost connection to the controller", self.last_joint_positions)
        q = np.asarray(self._receive.getActualQ(), dtype=np.float64)
        if q.shape != (6,) or not np.all(np.isfinite(q)):
            raise ArmFaultError("the controller sent no valid joint state", self.last_joint_positions, f"{q!r}")
        self.last_joint_positions = q
        return q.copy()

    def fault(self) -> str | None:
        """The controller's reason the arm cannot move now, or None when it can."""
        r, c = self._receive, self._control
        if not r.isConnected() or not c.isConnected():
            return "lost connection to the controller"
        if r.isEmergencyStopped():
            return "emergency stop"
        if r.isProtectiveStopped():
            return "protective stop"
        mode = int(r.getSafetyMode())
        if mode not in (1, 2):
            return SAFETY_MODES.get(mode, f"safety mode {mode}")
        if not c.isProgramRunning():
            return "the control script is not running on the controller (remote control off, or stopped)"
        return None

    def _raise_fault(self, reason: str, detail: str = "") -> None:
        try:
            if self._receive.isConnected():
                self.joint_positions()
        except DeviceError:
            pass
        raise ArmFaultError(reason, self.last_joint_positions, detail)

    # ------------------------------------------------------------------ motion

    def execute(self, trajectory: JointTrajectory) -> None:
        """Run ``trajectory`` to its end (blocking). ValueError for the wrong joints; LimitError (nothing
        sent) for a trajectory beyond the limits or not starting where the arm is; ArmFaultError when
        the controller stops the arm, the connection drops, the motion hangs, or :meth:`stop` is called."""
        if not isinstance(trajectory, JointTrajectory):
            raise ValueError(f"trajectory: expected a JointTrajectory, got {type(trajectory).__name__}")
        if trajectory.joint_names != UR_JOINTS:
            raise ValueError(f"trajectory.joint_names: expected {list(UR_JOINTS)}, got {list(trajectory.joint_names)}")
        cfg = self.config
        scale = cfg.speed_fraction if cfg.mode == "servo" else 1.0
        if cfg.mode == "servo":
            self._limits.check(trajectory, scale)
        else:  # moveJ times the motion itself, at the configured (limited) speed: check the geometry only
            self._limits.check_positions(trajectory)
        if not self._moving.acquire(blocking=False):
            raise DeviceError("arm: a trajectory is already running")
        try:
            self._stop.clear()
            reason = self.fault()
            if reason is not None:
                self._raise_fault(reason, "before the motion")
            q = self.joint_positions()
            off = float(np.max(np.abs(q - trajectory.start)))
            if off > math.radians(cfg.start_tolerance_deg):
                raise LimitError(
                    f"arm: the trajectory starts {math.degrees(off):.2f} deg from the arm's joints "
                    f"(start_tolerance_deg {cfg.start_tolerance_deg:g}); nothing sent"
                )
            if cfg.mode == "path":
                self._run_path(trajectory)
            else:
                self._run_servo(trajectory)
            q = self.joint_positions()
            miss = float(np.max(np.abs(q - trajectory.end)))
            if miss > math.radians(cfg.goal_tolerance_deg):
                self._raise_fault("the motion ended short of its goal", f"{math.degrees(miss):.2f} deg off")
        finally:
            self._moving.release()

    def _waypoints(self, trajectory: JointTrajectory) -> NDArray[np.float64]:
        """(M, 6) the trajectory's points thinned to at most ``max_waypoints`` (first and last kept)."""
        q = trajectory.positions
        if len(q) <= self.config.max_waypoints:
            return q
        idx = np.unique(np.round(np.linspace(0, len(q) - 1, self.config.max_waypoints)).astype(int))
        return q[idx]

    def _run_path(self, trajectory: JointTrajectory) -> None:
        cfg = self.config
        speed = math.radians(cfg.max_joint_speed_deg) * cfg.speed_fraction
        acc = math.radians(cfg.max_joint_acceleration_deg) * cfg.acceleration_fraction
        waypoints = self._waypoints(trajectory)
        path = [[*map(float, w), speed, acc, cfg.blend_m] for w in waypoints]
        path[-1][-1] = 0.0  # the controller requires no blend at the last point
        steps = np.max(np.abs(np.diff(waypoints, axis=0)), axis=1) if len(waypoints) > 1 else np.zeros(0)
        expected = float(np.sum(steps / speed + speed / acc))
        deadline = time.monotonic() + 1.5 * expected + cfg.timeout_margin_s
        # Progress is >= 0 while an async operation runs; between operations it is negative and toggles
        # between two values, so a negative value other than the one before the command means "finished"
        # (the command may be acknowledged before the operation starts: the same value means "not yet").
        idle_before = self._control.getAsyncOperationProgress()
        if not self._call(lambda: self._control.moveJ(path, True), "moveJ"):
            self._raise_fault(self.fault() or "the controller refused the motion", "moveJ returned false")
        while True:
            time.sleep(cfg.poll_s)
            self._watch(deadline, lambda: self._control.stopJ(2.0, False))
            progress = self._control.getAsyncOperationProgress()
            if progress < 0 and progress != idle_before:
                return

    def _run_servo(self, trajectory: JointTrajectory) -> None:
        cfg = self.config
        dt = 1.0 / cfg.servo_rate_hz
        duration = trajectory.duration / cfg.speed_fraction
        ticks = np.arange(0.0, duration + dt, dt)
        deadline = time.monotonic() + 1.5 * duration + cfg.timeout_margin_s
        control = self._control
        try:
            for t in ticks:
                start = control.initPeriod()
                q = trajectory.sample(min(t, duration) * cfg.speed_fraction)
                if not self._call(
                    lambda q=q: control.servoJ(list(map(float, q)), 0.0, 0.0, dt, cfg.lookahead_s, cfg.servo_gain),
                    "servoJ",
                ):
                    self._raise_fault(
                        self.fault() or "the controller refused the servo command", "servoJ returned false"
                    )
                self._watch(deadline, lambda: control.servoStop(10.0))
                control.waitPeriod(start)
        finally:
            if control.isConnected():
                control.servoStop(10.0)

    def _call(self, fn: Callable[[], Any], what: str) -> Any:
        """A control command; ur_rtde raises RuntimeError when the script died: report the controller's reason."""
        try:
            return fn()
        except RuntimeError as exc:
            self._raise_fault(self.fault() or f"{what} failed", str(exc))

    def _watch(self, deadline: float, halt: Callable[[], Any]) -> None:
        """One check of a running motion: fault, stop request or hang -> halt the arm and raise ArmFaultError."""
        reason = self.fault()
        if reason is not None:
            self._raise_fault(reason, "during the motion")
        with contextlib.suppress(DeviceError):
            self.joint_positions()
        if self._stop.is_set():
            halt()
            self._raise_fault("stopped on request")
        if time.monotonic() > deadline:
            halt()
            self._raise_fault("the motion did not finish in time", "timeout")

    def stop(self) -> None:
        """Halt a running motion at once (from any thread); when nothing runs, a harmless stopJ."""
        self._stop.set()
        if not self._moving.locked():
            try:
                if self._control.isConnected():
                    self._control.stopJ(2.0, False)
            except RuntimeError:
                pass

    def describe(self) -> str:
        """One line for ``nbv devices check``: host, mode and joints in degrees."""
        q = self.joint_positions()
        joints = ", ".join(f"{math.degrees(v):.1f}" for v in q)
        return f"UR at {self.config.host}, {self.config.mode} mode, joints [{joints}] deg"
