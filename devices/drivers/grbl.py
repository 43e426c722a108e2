"""A stepper turntable on GRBL firmware over a serial port (``pyserial``, extra ``[turntable]``).

GRBL (1.1) is the common open firmware of stepper controllers (an Arduino + CNC shield, or any board that
speaks it). The plate's motor is one GRBL axis (``X`` by default) whose units are scaled so that
``units_per_degree`` units turn the plate one degree (set GRBL's ``$100`` steps/unit accordingly, e.g.
steps per motor revolution x microsteps x gear ratio / 360 for 1 unit = 1 degree).

Protocol used: a soft reset (``Ctrl-X``) and the ``Grbl 1.1x`` banner on connect; ``$H`` homing when
configured; ``G90 G0 X<units>`` moves, acknowledged by ``ok`` (``error:N`` refuses); status polled with
the real-time ``?`` (``<Idle|MPos:...|...>``) until the plate is idle at the target; ``ALARM:N`` or an
``Alarm`` state is a DeviceError with the alarm's meaning; no answer within the timeouts is a
DeviceTimeoutError. ``stop()`` sends a feed hold (``!``); the moving call then waits for the hold to
complete and resets GRBL (safe after a hold: the position is kept), dropping the rest of the move.

For move capture, :meth:`GrblTurntable.record_plate` keeps the plate angle of every status report with the host
clock's time of its arrival (the reports a turn polls every ``poll_s``; an ``Idle`` one holds until the next): the
serial port is never read from a second thread.
"""

from __future__ import annotations

import math
import threading
import time
from dataclasses import dataclass
from typing import Any

from devices.drivers.common import import_vendor
from devices.drivers.plate import PlateScale, check_angle, wrap_deg
from devices.movestream import StampedSeries
from devices.protocols import DeviceError
from devices.timeout import DeviceTimeoutError
from planner.validate import finite, integer, require

ALARMS = {
    1: "hard limit triggered",
    2: "soft limit: motion target exceeds machine travel",
    3: "reset while in motion (position lost, re-home)",
    4: "probe fail",
    5: "probe fail",
    6: "homing fail: reset during homing",
    7: "homing fail: safety door opened during homing",
    8: "homing fail: could not clear the limit switch",
    9: "homing fail: limit switch not found",
    10: "homing fail: second dual-axis switch not found",
}
"""GRBL 1.1 alarm codes."""

ERRORS = {
    1: "expected command letter",
    2: "bad number format",
    3: "invalid $ statement",
    8: "not idle",
    9: "G-code locked out during alarm or jog state",
    15: "travel exceeds machine travel",
    20: "unsupported or invalid g-code command",
    22: "feed rate has not yet been set or is undefined",
}
"""GRBL 1.1 error codes the driver can cause, and their meaning."""


@dataclass(frozen=True)
class GrblConfig:
    """``[devices.turntable] driver = "grbl"``."""

    port: str = ""
    """Serial port (``/dev/ttyUSB0``, ``/dev/ttyACM0``, ``COM3``) or a pyserial URL (required)."""
    baudrate: int = 115200
    """Serial speed, baud (GRBL 1.1: 115200)."""
    axis: str = "X"
    """The GRBL axis that turns the plate: X, Y, Z or A."""
    units_per_degree: float = 1.0
    """GRBL axis units per degree of plate rotation."""
    invert: bool = False
    """True when positive axis motion turns the plate clockwise seen from above."""
    zero_offset_deg: float = 0.0
    """The plate angle at machine position 0 (after homing), degrees."""
    home_on_connect: bool = False
    """Run the homing cycle ($H) when connecting (needs homing switches and $22=1)."""
    continuous: bool = True
    """The plate may turn without limit (each move takes the short way); false: it stays in [-180, 180] deg."""
    tolerance_deg: float = 0.05
    """A move has arrived when the plate is within this of the target, degrees."""
    command_timeout_s: float = 2.0
    """Longest wait for ``ok`` to a command or for a status report, seconds."""
    move_timeout_s: float = 60.0
    """Longest wait for a move to finish, seconds."""
    homing_timeout_s: float = 60.0
    """Longest wait for the homing cycle, seconds."""
    startup_s: float = 3.0
    """Longest wait for the GRBL banner after opening the port and a soft reset, seconds."""
    poll_s: float = 0.05
    """Status polling period while moving, seconds."""

    def __post_init__(self) -> None:
        p = "devices.turntable."
        require(isinstance(self.port, str) and self.port.strip() != "", f"{p}port: required (e.g. /dev/ttyUSB0)")
        require(integer(self.baudrate) and self.baudrate > 0, f"{p}baudrate: must be a positive integer")
        require(self.axis in ("X", "Y", "Z", "A"), f"{p}axis: one of X, Y, Z, A, got {self.axis!r}")
        require(
            finite(self.units_per_degree) and self.units_per_degree > 0,
            f"{p}units_per_degree: must be > 0, got {self.units_per_degree!r}",
        )
        for name in ("invert", "home_on_connect", "continuous"):
            require(isinstance(getattr(self, name), bool), f"{p}{name}: expected true/false")
        require(finite(self.zero_offset_deg), f"{p}zero_offset_deg: must be finite, got {self.zero_offset_deg!r}")
        for name in ("tolerance_deg", "command_timeout_s", "move_timeout_s", "homing_timeout_s", "startup_s", "poll_s"):
            v = getattr(self, name)
            require(finite(v) and v > 0, f"{p}{name}: must be > 0, got {v!r}")


class GrblTurntable:
    """A GRBL-driven turntable behind :class:`devices.protocols.Turntable` (angles in radians), plus ``stop``.

    Opening connects, resets GRBL, waits for its banner and homes if configured; a GRBL in alarm after
    that is a DeviceError telling to home or unlock. ``close()`` (or ``with``) releases the port.
    """

    def __init__(self, config: GrblConfig) -> None:
        self.config = config
        self._scale = PlateScale(config.units_per_degree, config.invert, config.zero_offset_deg, config.continuous)
        serial = import_vendor("serial", "turntable", "GRBL turntable")
        self._write_lock = threading.Lock()
        self._recorders: list[StampedSeries] = []
        self._stop = threading.Event()
        self._moving = False
        self._buffer = b""
        self.last_alarm: str | None = None
        self.version = ""
        try:
            self._port: Any = serial.serial_for_url(config.port, baudrate=config.baudrate, timeout=0.02)
        except (serial.SerialException, OSError, ValueError) as exc:
            raise DeviceError(f"turntable: cannot open {config.port!r} ({exc})") from None
        try:
            self._reset()
            if config.home_on_connect:
                self.home()
            state, _ = self._status()
            if state.startswith("Alarm"):
                raise DeviceError(
                    f"turntable: GRBL is in alarm after reset ({self.last_alarm or 'homing required'}); "
                    "home it (home_on_connect = true) or unlock it with $X"
                )
        except BaseException:
            self.close()
            raise

    def close(self) -> None:
        self._port.close()

    def __enter__(self) -> GrblTurntable:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    # ------------------------------------------------------------------ serial protocol

    def _write(self, data: bytes) -> None:
        with self._write_lock:
            self._port.write(data)

    def _readline(self, deadline: float, what: str) -> str:
        """The next non-empty line; ``ALARM:N`` lines are remembered. DeviceTimeoutError at ``deadline``."""
        while True:
            if b"\n" in self._buffer:
                raw, self._buffer = self._buffer.split(b"\n", 1)
                line = raw.decode("ascii", "replace").strip()
                if not line:
                    continue
                if line.startswith("ALARM:"):
                    code = line[6:]
                    meaning = ALARMS.get(int(code), "unknown alarm") if code.isdigit() else code
                    self.last_alarm = f"ALARM:{code} {meaning}"
                return line
            if time.monotonic() > deadline:
                raise DeviceTimeoutError(f"turntable: no answer from GRBL on {self.config.port} to {what} (timeout)")
            self._buffer += self._port.read(max(1, self._port.in_waiting))

    def _reset(self) -> None:
        self._port.reset_input_buffer()
        self._buffer = b""
        self._write(b"\x18")
        deadline = time.monotonic() + self.config.startup_s
        while True:
            line = self._readline(deadline, "a soft reset (no Grbl banner)")
            if line.startswith("Grbl"):
                self.version = line.split("[")[0].strip()
                return

    def _command(self, line: str, timeout: float) -> None:
        """Send one line and wait for ``ok``; ``error:N`` and alarms are DeviceErrors naming the command."""
        self._write(line.encode("ascii") + b"\n")
        deadline = time.monotonic() + timeout
        while True:
            reply = self._readline(deadline, repr(line))
            if reply == "ok":
                return
            if reply.startswith("error:"):
                code = reply[6:]
                meaning = ERRORS.get(int(code), "see the GRBL error codes") if code.isdigit() else code
                raise DeviceError(f"turntable: GRBL refused {line!r}: error:{code} {meaning}")
            if reply.startswith("ALARM:"):
                raise DeviceError(f"turntable: GRBL alarm on {line!r}: {self.last_alarm}")

    def _status(self) -> tuple[str, float]:
        """(state, machine position of the plate axis in GRBL units) from a ``?`` report."""
        self._write(b"?")
        deadline = time.monotonic() + self.config.command_timeout_s
        while True:
            line = self._readline(deadline, "a status request '?'")
            if line.startswith("<") and line.endswith(">"):
                fields = line[1:-1].split("|")
                for f in fields[1:]:
                    if f.startswith(("MPos:", "WPos:")):
                        values = [float(v) for v in f[5:].split(",")]
                        index = "XYZA".index(self.config.axis)
                        if index >= len(values):
                            raise DeviceError(f"turntable: GRBL reports no {self.config.axis} axis: {line}")
                        for series in list(self._recorders):
                            plate = math.radians(self._plate_deg(values[index]))
                            series.add(time.time(), plate, rest=fields[0] == "Idle")
                        return fields[0], values[index]
                raise DeviceError(f"turntable: GRBL status without a position: {line}")

    def _plate_deg(self, units: float) -> float:
        return self._scale.plate_deg(units)

    # ------------------------------------------------------------------ Turntable protocol

    @property
    def angle(self) -> float:
        """The plate angle, radians in (-pi, pi]."""
        _, units = self._status()
        return math.radians(wrap_deg(self._plate_deg(units)))

    def record_plate(self) -> StampedSeries:
        """A history of the plate angle (radians, host clock), from a status report now on, until
        :meth:`stop_recording` (:class:`devices.movestream.PlateRecorder`; call it from the thread that moves)."""
        series = StampedSeries(angle=True)
        self._recorders.append(series)
        self._status()
        return series

    def stop_recording(self, series: StampedSeries) -> None:
        if series in self._recorders:
            self._recorders.remove(series)

    def home(self) -> None:
        """Run the homing cycle ($H); the plate is then at ``zero_offset_deg``."""
        self._command("$H", self.config.homing_timeout_s)

    def rotate_to(self, angle: float) -> None:
        """Turn the plate to ``angle`` (radians) and wait until it is there (the short way when continuous)."""
        wanted = check_angle(angle)
        cfg = self.config
        state, units = self._status()
        if state.startswith("Alarm"):
            raise DeviceError(f"turntable: GRBL is in alarm ({self.last_alarm or 'unlock or home it'}); not moving")
        target = self._scale.target_deg(self._plate_deg(units), wanted)
        goal = self._scale.units(target)
        self._stop.clear()
        self._moving = True
        try:
            self._command(f"G90 G0 {cfg.axis}{goal:.4f}", cfg.command_timeout_s)
            deadline = time.monotonic() + cfg.move_timeout_s
            while True:
                state, units = self._status()
                if state.startswith("Alarm"):
                    raise DeviceError(
                        f"turntable: GRBL alarm during the move ({self.last_alarm or 'alarm state'}) "
                        f"at {self._plate_deg(units):.2f} deg"
                    )
                if self._stop.is_set():
                    self._halt()
                    raise DeviceError(f"turntable: stopped on request at {self._plate_deg(self._status()[1]):.2f} deg")
                if state == "Idle":
                    if abs(self._plate_deg(units) - target) <= cfg.tolerance_deg:
                        return
                    raise DeviceError(
                        f"turntable: GRBL is idle at {self._plate_deg(units):.2f} deg, short of {target:.2f} deg"
                    )
                if time.monotonic() > deadline:
                    self._halt()
                    raise DeviceTimeoutError(
                        f"turntable: the move to {target:.2f} deg did not finish within {cfg.move_timeout_s:g} s"
                    )
                time.sleep(cfg.poll_s)
        finally:
            self._moving = False

    def _halt(self) -> None:
        """Feed hold, wait for the plate to stand still, then a soft reset to drop the rest of the move."""
        self._write(b"!")
        deadline = time.monotonic() + self.config.command_timeout_s
        while time.monotonic() < deadline:
            state, _ = self._status()
            if state in ("Hold:0", "Idle") or state.startswith("Alarm"):
                break
            time.sleep(self.config.poll_s)
        self._reset()

    def stop(self) -> None:
        """Stop a running move at once (from any thread): a feed hold now; the moving call resets GRBL."""
        self._stop.set()
        if self._moving:
            self._write(b"!")

    def describe(self) -> str:
        """One line for ``nbv devices check``."""
        state, units = self._status()
        return f"{self.version or 'GRBL'} on {self.config.port}, {state}, plate at {wrap_deg(self._plate_deg(units)):.2f} deg"
