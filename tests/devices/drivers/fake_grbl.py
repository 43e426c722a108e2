"""A fake GRBL 1.1 firmware speaking the serial protocol on a pseudo terminal (``os.openpty`` + a thread).

The driver opens ``FakeGrbl.port`` (the pty's slave device, e.g. ``/dev/pts/7``) with pyserial, exactly as
it would open ``/dev/ttyUSB0``. The firmware answers: ``Ctrl-X`` (banner, keeps the position, clears a
hold; in motion it raises ALARM:3 like the real one), ``?`` (``<State|MPos:x,y,z|FS:f,0>``), ``!`` (feed
hold: decelerates to ``Hold:0``), ``$H`` (homing: ``Home`` for ``homing_s``, then position 0), ``$X``
(unlock), ``G90 G0 X<u>`` (rapid at ``rate`` units/s), everything else ``error:20``; moves in alarm
``error:9``. Faults: ``alarm_after_s`` (ALARM:1 hard limit that many seconds into the next move),
``silent`` (stops answering), ``start_in_alarm`` (as after power-up with homing enabled).
"""

from __future__ import annotations

import contextlib
import os
import re
import select
import threading
import time
import tty


class FakeGrbl:
    """GRBL on a pty; use as a context manager (the thread and the pty end on exit)."""

    def __init__(self, *, rate: float = 360.0, homing_s: float = 0.1, start_in_alarm: bool = False) -> None:
        self.rate = rate
        self.homing_s = homing_s
        self.position = 0.0
        self.state = "Alarm" if start_in_alarm else "Idle"
        self.alarm_after_s: float | None = None
        self.silent = False
        self.lines: list[str] = []
        self._move: tuple[float, float, float] | None = None  # (t0, start, target)
        self._alarm_at: float | None = None
        self._hold_at: float | None = None
        self._homing_until: float | None = None
        self._lock = threading.Lock()
        self._master, self._slave = os.openpty()
        tty.setraw(self._slave)
        self.port = os.ttyname(self._slave)
        self._closing = threading.Event()
        self._thread = threading.Thread(target=self._serve, name="fake-grbl", daemon=True)
        self._thread.start()

    def __enter__(self) -> FakeGrbl:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    def close(self) -> None:
        self._closing.set()
        self._thread.join(timeout=2)
        for fd in (self._master, self._slave):
            with contextlib.suppress(OSError):
                os.close(fd)

    # ------------------------------------------------------------------ simulation

    def _send(self, text: str) -> None:
        if not self.silent:
            os.write(self._master, text.encode("ascii") + b"\r\n")

    def _advance(self) -> None:
        now = time.monotonic()
        if self._homing_until is not None and now >= self._homing_until:
            self._homing_until, self.position, self.state = None, 0.0, "Idle"
            self._send("ok")
        if self._move is None:
            return
        _t0, _start, target = self._move
        if self._alarm_at is not None and now >= self._alarm_at:
            self.position = self._at(self._alarm_at)
            self._move, self._alarm_at, self.state = None, None, "Alarm"
            self._send("ALARM:1")
            return
        if self._hold_at is not None:
            if now - self._hold_at > 0.05:  # decelerated
                self.position = self._at(self._hold_at + 0.05)
                self.state = "Hold:0"
            return
        self.position = self._at(now)
        if self.position == target:
            self._move, self.state = None, "Idle"

    def _at(self, t: float) -> float:
        assert self._move is not None
        t0, start, target = self._move
        step = self.rate * max(t - t0, 0.0)
        return target if step >= abs(target - start) else start + step * (1 if target > start else -1)

    def _realtime(self, ch: bytes) -> None:
        if ch == b"?":
            self._send(
                f"<{self.state}|MPos:{self.position:.3f},0.000,0.000|FS:{self.rate * 60 if self._move else 0:.0f},0>"
            )
        elif ch == b"!":
            if self._move is not None and self._hold_at is None:
                self._hold_at, self.state = time.monotonic(), "Hold:1"
        elif ch == b"\x18":
            if self._move is not None and self.state.startswith("Run"):
                self._move, self.state = None, "Alarm"  # reset in motion loses the position
                self._send("ALARM:3")
            else:
                self._move, self._hold_at = None, None
                if not self.state.startswith("Alarm"):
                    self.state = "Idle"
            self._send("Grbl 1.1h ['$' for help]")

    def _line(self, line: str) -> None:
        self.lines.append(line)
        if line == "$H":
            self.state, self._homing_until = "Home", time.monotonic() + self.homing_s
            return
        if line == "$X":
            self.state = "Idle"
            self._send("[MSG:Caution: Unlocked]")
            self._send("ok")
            return
        m = re.fullmatch(r"G90 G0 X(-?\d+(?:\.\d+)?)", line)
        if not m:
            self._send("error:20")
            return
        if self.state.startswith("Alarm"):
            self._send("error:9")
            return
        self._move = (time.monotonic(), self.position, float(m.group(1)))
        self.state = "Run"
        if self.alarm_after_s is not None:
            self._alarm_at, self.alarm_after_s = time.monotonic() + self.alarm_after_s, None
        self._send("ok")

    def _serve(self) -> None:
        pending = b""
        while not self._closing.is_set():
            ready, _, _ = select.select([self._master], [], [], 0.005)
            with self._lock:
                self._advance()
                if not ready:
                    continue
                try:
                    data = os.read(self._master, 1024)
                except OSError:
                    continue
                for i in range(len(data)):
                    ch = data[i : i + 1]
                    if ch in (b"?", b"!", b"~", b"\x18"):
                        self._realtime(ch)
                    elif ch in (b"\n", b"\r"):
                        if pending.strip():
                            self._line(pending.decode("ascii").strip())
                        pending = b""
                    else:
                        pending += ch
