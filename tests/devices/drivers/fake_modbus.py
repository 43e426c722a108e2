"""A fake Modbus RTU position drive on a pseudo terminal, with the default register map of the driver.

Function codes 3 (read holding registers), 6 (write one) and 16 (write several), CRC-checked RTU
frames; requests to another slave address are ignored, unknown registers get exception 2. The motor
moves at ``rate`` steps/s after ``move_command``; ``stop_command`` freezes it; ``home_command`` homes
to 0 in ``homing_s``. Faults: ``alarm_after_s`` (alarm 21 that many seconds into the next move),
``silent`` (no answers).
"""

from __future__ import annotations

import contextlib
import os
import select
import struct
import threading
import time
import tty

POSITION, TARGET, COMMAND, STATUS, ALARM = 0, 2, 4, 5, 6


def crc16(data: bytes) -> bytes:
    crc = 0xFFFF
    for byte in data:
        crc ^= byte
        for _ in range(8):
            crc = (crc >> 1) ^ 0xA001 if crc & 1 else crc >> 1
    return struct.pack("<H", crc)


class FakeModbusDrive:
    """The drive on a pty (``port`` is the device the driver opens); a context manager."""

    def __init__(self, *, address: int = 1, rate: float = 36000.0, homing_s: float = 0.1) -> None:
        self.address = address
        self.rate = rate
        self.homing_s = homing_s
        self.position = 0
        self.target = 0
        self.alarm = 0
        self.alarm_after_s: float | None = None
        self.silent = False
        self.commands: list[int] = []
        self._move: tuple[float, int, int] | None = None
        self._alarm_at: float | None = None
        self._master, self._slave = os.openpty()
        tty.setraw(self._slave)
        self.port = os.ttyname(self._slave)
        self._closing = threading.Event()
        self._thread = threading.Thread(target=self._serve, name="fake-modbus", daemon=True)
        self._thread.start()

    def __enter__(self) -> FakeModbusDrive:
        return self

    def __exit__(self, *exc: object) -> None:
        self._closing.set()
        self._thread.join(timeout=2)
        for fd in (self._master, self._slave):
            with contextlib.suppress(OSError):
                os.close(fd)

    # ------------------------------------------------------------------ the motor

    def _advance(self) -> None:
        if self._move is None:
            return
        now = time.monotonic()
        t0, start, goal = self._move
        at = now if self._alarm_at is None else min(now, self._alarm_at)
        step = int(self.rate * (at - t0))
        self.position = goal if step >= abs(goal - start) else start + step * (1 if goal > start else -1)
        if self._alarm_at is not None and now >= self._alarm_at:
            self._move, self._alarm_at, self.alarm = None, None, 21
        elif self.position == goal:
            self._move = None

    def _status(self) -> int:
        return (1 if self._move is not None else 0) | (2 if self.alarm else 0)

    def _read(self, reg: int) -> int | None:
        pos, tgt = self.position & 0xFFFFFFFF, self.target & 0xFFFFFFFF
        values = {
            POSITION: pos >> 16,
            POSITION + 1: pos & 0xFFFF,
            TARGET: tgt >> 16,
            TARGET + 1: tgt & 0xFFFF,
            COMMAND: 0,
            STATUS: self._status(),
            ALARM: self.alarm,
        }
        return values.get(reg)

    def _write(self, reg: int, value: int) -> bool:
        if reg == TARGET:
            self.target = (value << 16) | (self.target & 0xFFFF)
        elif reg == TARGET + 1:
            self.target = (self.target & 0xFFFF0000) | value
            if self.target >= 2**31:
                self.target -= 2**32
        elif reg == COMMAND:
            self.commands.append(value)
            now = time.monotonic()
            if value == 1 and not self.alarm:
                self._move = (now, self.position, self.target)
                if self.alarm_after_s is not None:
                    self._alarm_at, self.alarm_after_s = now + self.alarm_after_s, None
            elif value == 2:
                self._move = None
            elif value == 3:
                self._move = (now, self.position, 0)
        else:
            return False
        return True

    # ------------------------------------------------------------------ RTU frames

    def _answer(self, frame: bytes) -> bytes | None:
        fc = frame[1]
        if fc == 3:
            start, count = struct.unpack(">HH", frame[2:6])
            values = [self._read(r) for r in range(start, start + count)]
            if any(v is None for v in values):
                return bytes([self.address, fc | 0x80, 2])
            return bytes([self.address, fc, 2 * count]) + b"".join(struct.pack(">H", v) for v in values)
        if fc == 6:
            reg, value = struct.unpack(">HH", frame[2:6])
            return frame[:6] if self._write(reg, value) else bytes([self.address, fc | 0x80, 2])
        if fc == 16:
            start, count = struct.unpack(">HH", frame[2:6])
            values = struct.unpack(f">{count}H", frame[7 : 7 + 2 * count])
            ok = all(self._write(start + i, v) for i, v in enumerate(values))
            return frame[:6] if ok else bytes([self.address, fc | 0x80, 2])
        return bytes([self.address, fc | 0x80, 1])

    @staticmethod
    def _frame_length(buf: bytes) -> int | None:
        if len(buf) < 2:
            return None
        if buf[1] in (3, 6):
            return 8
        if buf[1] == 16:
            return 9 + buf[6] if len(buf) >= 7 else None
        return 4

    def _serve(self) -> None:
        buf = b""
        while not self._closing.is_set():
            ready, _, _ = select.select([self._master], [], [], 0.005)
            self._advance()
            if not ready:
                continue
            try:
                buf += os.read(self._master, 256)
            except OSError:
                continue
            while (n := self._frame_length(buf)) is not None and len(buf) >= n:
                frame, buf = buf[:n], buf[n:]
                if crc16(frame[:-2]) != frame[-2:]:
                    buf = b""
                    break
                if frame[0] != self.address or self.silent:
                    continue
                reply = self._answer(frame)
                if reply is not None:
                    os.write(self._master, reply + crc16(reply))
