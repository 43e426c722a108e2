"""A turntable on a Modbus RTU stepper/servo drive (``minimalmodbus``, extra ``[turntable]``).

Integrated stepper and servo drives with an RS-485 port (Leadshine, JMC, Oriental Motor, ...) run
position moves from holding registers. Their register maps differ, so this driver uses a generic
position-mode map whose addresses and codes are all config fields (set them from the drive's manual):

- ``position_register``: actual position, 32-bit signed, two registers, high word first (read);
- ``target_register``: target position, 32-bit signed, two registers (written before a move);
- ``command_register``: written with ``move_command`` (go to target), ``stop_command`` (decelerate
  and stop) or ``home_command`` (homing cycle);
- ``status_register``: bit ``moving_bit`` set while moving, bit ``alarm_bit`` set in alarm;
- ``alarm_register``: the drive's alarm code while the alarm bit is set.

Positions are in drive steps; ``steps_per_degree`` turns them into plate degrees (see
:mod:`devices.drivers.plate`). No answer within ``response_timeout_s`` is a DeviceTimeoutError, an
exception response or a garbled frame a DeviceError naming the register.
"""

from __future__ import annotations

import math
import threading
import time
from dataclasses import dataclass
from typing import Any

from devices.drivers.common import import_vendor
from devices.drivers.plate import PlateScale, check_angle, wrap_deg
from devices.protocols import DeviceError
from devices.timeout import DeviceTimeoutError
from planner.validate import finite, integer, require

REGISTERS = ("position_register", "target_register", "command_register", "status_register", "alarm_register")


@dataclass(frozen=True)
class ModbusTurntableConfig:
    """``[devices.turntable] driver = "modbus"``."""

    port: str = ""
    """Serial port of the RS-485 adapter (``/dev/ttyUSB0``), required."""
    slave_address: int = 1
    """The drive's Modbus address, 1..247."""
    baudrate: int = 19200
    """Serial speed, baud (the drive's setting)."""
    parity: str = "N"
    """Serial parity: "N", "E" or "O" (the drive's setting)."""
    steps_per_degree: float = 100.0
    """Drive steps (position units) per degree of plate rotation."""
    invert: bool = False
    """True when positive steps turn the plate clockwise seen from above."""
    zero_offset_deg: float = 0.0
    """The plate angle at drive position 0, degrees."""
    continuous: bool = True
    """The plate may turn without limit (short way); false: targets stay in [-180, 180] deg."""
    home_on_connect: bool = False
    """Run the drive's homing cycle when connecting."""
    position_register: int = 0
    """Holding register of the actual position (32-bit signed, high word first)."""
    target_register: int = 2
    """Holding register of the target position (32-bit signed, high word first)."""
    command_register: int = 4
    """Holding register taking the command codes."""
    status_register: int = 5
    """Holding register of the status bits."""
    alarm_register: int = 6
    """Holding register of the alarm code."""
    move_command: int = 1
    """Command code: move to the target."""
    stop_command: int = 2
    """Command code: decelerate and stop."""
    home_command: int = 3
    """Command code: run the homing cycle."""
    moving_bit: int = 0
    """Status bit set while the motor moves (or homes)."""
    alarm_bit: int = 1
    """Status bit set while the drive is in alarm."""
    tolerance_deg: float = 0.05
    """A move has arrived when the plate is within this of the target, degrees."""
    response_timeout_s: float = 0.2
    """Longest wait for a Modbus answer, seconds."""
    move_timeout_s: float = 60.0
    """Longest wait for a move or homing to finish, seconds."""
    poll_s: float = 0.05
    """Status polling period while moving, seconds."""

    def __post_init__(self) -> None:
        p = "devices.turntable."
        require(isinstance(self.port, str) and self.port.strip() != "", f"{p}port: required (e.g. /dev/ttyUSB0)")
        require(
            integer(self.slave_address) and 1 <= self.slave_address <= 247,
            f"{p}slave_address: must be an integer in 1..247, got {self.slave_address!r}",
        )
        require(integer(self.baudrate) and self.baudrate > 0, f"{p}baudrate: must be a positive integer")
        require(self.parity in ("N", "E", "O"), f"{p}parity: 'N', 'E' or 'O', got {self.parity!r}")
        require(
            finite(self.steps_per_degree) and self.steps_per_degree > 0,
            f"{p}steps_per_degree: must be > 0, got {self.steps_per_degree!r}",
        )
        for name in ("invert", "continuous", "home_on_connect"):
            require(isinstance(getattr(self, name), bool), f"{p}{name}: expected true/false")
        require(finite(self.zero_offset_deg), f"{p}zero_offset_deg: must be finite")
        for name in (*REGISTERS, "move_command", "stop_command", "home_command"):
            v = getattr(self, name)
            require(integer(v) and 0 <= v <= 0xFFFF, f"{p}{name}: must be an integer in 0..65535, got {v!r}")
        for name in ("moving_bit", "alarm_bit"):
            v = getattr(self, name)
            require(integer(v) and 0 <= v <= 15, f"{p}{name}: must be a bit number 0..15, got {v!r}")
        for name in ("tolerance_deg", "response_timeout_s", "move_timeout_s", "poll_s"):
            v = getattr(self, name)
            require(finite(v) and v > 0, f"{p}{name}: must be > 0, got {v!r}")


class ModbusTurntable:
    """A Modbus RTU drive turning the plate, behind :class:`devices.protocols.Turntable` plus ``stop``."""

    def __init__(self, config: ModbusTurntableConfig) -> None:
        self.config = config
        self._mm: Any = import_vendor("minimalmodbus", "turntable", "Modbus turntable")
        self._scale = PlateScale(config.steps_per_degree, config.invert, config.zero_offset_deg, config.continuous)
        self._lock = threading.Lock()  # one Modbus transaction at a time (stop() comes from another thread)
        self._stop = threading.Event()
        try:
            self._bus = self._mm.Instrument(config.port, config.slave_address)
        except (OSError, ValueError) as exc:
            raise DeviceError(f"turntable: cannot open {config.port!r} ({exc})") from None
        self._bus.serial.baudrate = config.baudrate
        self._bus.serial.parity = config.parity
        self._bus.serial.timeout = config.response_timeout_s
        self._bus.close_port_after_each_call = False
        try:
            self._status()
            if config.home_on_connect:
                self.home()
        except BaseException:
            self.close()
            raise

    def close(self) -> None:
        self._bus.serial.close()

    def __enter__(self) -> ModbusTurntable:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    # ------------------------------------------------------------------ Modbus transactions

    def _call(self, what: str, fn: Any, *args: Any, **kwargs: Any) -> Any:
        mm = self._mm
        with self._lock:
            try:
                return fn(*args, **kwargs)
            except mm.NoResponseError:
                raise DeviceTimeoutError(
                    f"turntable: no answer from Modbus slave {self.config.slave_address} on "
                    f"{self.config.port} to {what} (timeout)"
                ) from None
            except mm.ModbusException as exc:
                raise DeviceError(f"turntable: Modbus error on {what}: {exc}") from None
            except OSError as exc:
                raise DeviceError(f"turntable: serial error on {what}: {exc}") from None

    def _status(self) -> tuple[bool, int | None]:
        """(moving, alarm code or None)."""
        cfg = self.config
        bits = int(
            self._call(f"reading status register {cfg.status_register}", self._bus.read_register, cfg.status_register)
        )
        alarm = None
        if bits >> cfg.alarm_bit & 1:
            alarm = int(
                self._call(f"reading alarm register {cfg.alarm_register}", self._bus.read_register, cfg.alarm_register)
            )
        return bool(bits >> cfg.moving_bit & 1), alarm

    def _position(self) -> int:
        reg = self.config.position_register
        return int(self._call(f"reading position register {reg}", self._bus.read_long, reg, 3, True))

    def _command(self, code: int) -> None:
        reg = self.config.command_register
        self._call(f"writing command {code} to register {reg}", self._bus.write_register, reg, code)

    def _wait(self, what: str, target_deg: float | None) -> None:
        cfg = self.config
        deadline = time.monotonic() + cfg.move_timeout_s
        while True:
            moving, alarm = self._status()
            if alarm is not None:
                raise DeviceError(f"turntable: drive alarm {alarm} during {what} at {self._plate_deg():.2f} deg")
            if self._stop.is_set():
                self._command(cfg.stop_command)
                raise DeviceError(f"turntable: stopped on request at {self._plate_deg():.2f} deg")
            if not moving:
                if target_deg is None:
                    return
                at = self._plate_deg()
                if abs(at - target_deg) <= cfg.tolerance_deg:
                    return
                raise DeviceError(f"turntable: the drive stopped at {at:.2f} deg, short of {target_deg:.2f} deg")
            if time.monotonic() > deadline:
                self._command(cfg.stop_command)
                raise DeviceTimeoutError(f"turntable: {what} did not finish within {cfg.move_timeout_s:g} s")
            time.sleep(cfg.poll_s)

    def _plate_deg(self) -> float:
        return self._scale.plate_deg(self._position())

    # ------------------------------------------------------------------ Turntable protocol

    @property
    def angle(self) -> float:
        """The plate angle, radians in (-pi, pi]."""
        return math.radians(wrap_deg(self._plate_deg()))

    def home(self) -> None:
        """Run the drive's homing cycle and wait for it."""
        self._stop.clear()
        self._command(self.config.home_command)
        self._wait("homing", None)

    def rotate_to(self, angle: float) -> None:
        """Turn the plate to ``angle`` (radians) and wait until it is there."""
        wanted = check_angle(angle)
        cfg = self.config
        _, alarm = self._status()
        if alarm is not None:
            raise DeviceError(f"turntable: drive alarm {alarm}; clear it on the drive, not moving")
        target = self._scale.target_deg(self._plate_deg(), wanted)
        steps = round(self._scale.units(target))
        if not -(2**31) <= steps < 2**31:
            raise DeviceError(f"turntable: target {target:.1f} deg is {steps} steps, beyond 32 bits")
        self._stop.clear()
        reg = cfg.target_register
        self._call(f"writing the target to register {reg}", self._bus.write_long, reg, steps, True)
        self._command(cfg.move_command)
        self._wait(f"the move to {target:.2f} deg", target)

    def stop(self) -> None:
        """Stop a running move (from any thread): the stop command now; the moving call then raises."""
        self._stop.set()
        self._command(self.config.stop_command)

    def describe(self) -> str:
        """One line for ``nbv devices check``."""
        moving, alarm = self._status()
        state = f"alarm {alarm}" if alarm is not None else ("moving" if moving else "idle")
        return (
            f"Modbus drive {self.config.slave_address} on {self.config.port}, {state}, "
            f"plate at {wrap_deg(self._plate_deg()):.2f} deg"
        )
