"""Open the devices a cell file names: the set a supervised session drives, and ``nbv devices check``.

:func:`open_rig` connects the camera, the arm and the turntable of a :class:`devices.cellfile.CellFile` and
returns a :class:`Rig`; if one fails, the ones already open are closed and the error propagates.
:func:`check_devices` opens each device on its own, reads its state, and reports one line per device.

The seam with the session (see ``docs/hardware.md``): planning, inverse kinematics and collision checks
stay on our side and produce a turntable angle and a :class:`devices.trajectory.JointTrajectory`; the
rig executes them (``turntable.rotate_to``, ``arm.execute``), and the camera pose of a capture is
``rig.cell.T_base_camera(T_armbase_flange)`` from forward kinematics of ``arm.joint_positions()``.
"""

from __future__ import annotations

import contextlib
import math
import threading
from dataclasses import dataclass
from typing import Any

import numpy as np

from devices.cellfile import CellFile, DeviceSpec
from devices.drivers.registry import REGISTRY
from devices.protocols import CaptureError, DeviceError


def open_device(spec: DeviceSpec) -> Any:
    """Connect one configured device with its registered driver."""
    return REGISTRY[(spec.kind, spec.driver)].open(spec.config)


def _close(device: Any) -> None:
    close = getattr(device, "close", None)
    if callable(close):
        with contextlib.suppress(Exception):  # closing must not hide the error that made us close
            close()


@dataclass(eq=False)
class Rig:
    """The opened devices of one cell file (None where the file has no such section).

    camera: a :class:`devices.protocols.Camera`. arm: a :class:`devices.protocols.JointArm`.
    turntable: a :class:`devices.protocols.Turntable` (real drivers add ``stop()``). cell: the cell file
    (hand-eye transform, arm base, ``allow_auto``).
    """

    cell: CellFile
    camera: Any = None
    arm: Any = None
    turntable: Any = None

    def stop(self) -> list[str]:
        """Stop the arm and the turntable at once (each ``stop()`` in its own thread); returns the errors."""
        errors: list[str] = []
        movers = [d for d in (self.arm, self.turntable) if callable(getattr(d, "stop", None))]

        def run(device: Any) -> None:
            try:
                device.stop()
            except Exception as exc:
                errors.append(f"{type(device).__name__}: {exc}")

        threads = [threading.Thread(target=run, args=(d,), daemon=True) for d in movers]
        for t in threads:
            t.start()
        for t in threads:
            t.join(timeout=5.0)
        return errors

    def close(self) -> None:
        """Close every device (stop the arm's control script, release ports and pipelines)."""
        for device in (self.camera, self.arm, self.turntable):
            if device is not None:
                _close(device)

    def __enter__(self) -> Rig:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()


def open_rig(cell: CellFile) -> Rig:
    """Connect every device of ``cell`` (camera, arm, turntable, in that order). On a failure the devices
    already opened are closed and the DeviceError (or ValueError) propagates."""
    rig = Rig(cell)
    try:
        for spec in cell.devices():
            setattr(rig, spec.kind, open_device(spec))
    except BaseException:
        rig.close()
        raise
    return rig


@dataclass(frozen=True)
class DeviceCheck:
    """The result of checking one device: ``ok`` and a one-line message (its state, or the error)."""

    kind: str
    driver: str
    ok: bool
    message: str

    def line(self) -> str:
        return f"{self.kind:<10s} {self.driver:<10s} {'ok' if self.ok else 'FAILED':<7s} {self.message}"


def _state(kind: str, device: Any) -> str:
    """Read the device's state; one line."""
    describe = getattr(device, "describe", None)
    head = str(describe()) if callable(describe) else type(device).__name__
    if kind == "camera":
        try:
            frame = device.capture()
        except CaptureError:
            if getattr(device, "pose_source", True) is not None:
                raise
            k = device.intrinsics  # a simulated camera renders from the pose of the cell it is mounted in
            return f"{head}: {k.width}x{k.height}, renders once mounted in a cell (no test capture)"
        valid = frame.depth[frame.depth > 0]
        median = f", median depth {float(np.median(valid)):.3f} m" if valid.size else ""
        return f"{head}; test capture {valid.size} of {frame.depth.size} pixels with a return{median}"
    if kind == "arm":
        q = device.joint_positions()
        if callable(describe):
            return head
        return f"{head}: joints [{', '.join(f'{math.degrees(v):.1f}' for v in q)}] deg"
    angle = device.angle
    return head if callable(describe) else f"{head}: plate at {math.degrees(angle):.2f} deg"


def check_devices(cell: CellFile) -> list[DeviceCheck]:
    """Open each configured device on its own, read its state, close it: one DeviceCheck per device."""
    results = []
    for spec in cell.devices():
        device = None
        try:
            device = open_device(spec)
            results.append(DeviceCheck(spec.kind, spec.driver, True, _state(spec.kind, device)))
        except (DeviceError, ValueError, OSError) as exc:
            results.append(DeviceCheck(spec.kind, spec.driver, False, f"{type(exc).__name__}: {exc}"))
        finally:
            if device is not None:
                _close(device)
    return results
