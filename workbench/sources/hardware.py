"""The ``hardware`` session source: a supervised scan on the devices of a cell file, and its safety rules.

``nbv serve --cell cell.toml`` (or ``[server] cell = "cell.toml"``) makes ``hardware`` the default source of a
new session. The session's cell is a :class:`HardwareCell`: the rig's camera, arm and turntable
(:func:`devices.rig.open_rig`) with the arm model configured from the cell file (:func:`arm_cell_config`:
hand-eye transform, mount, joint limits, speed and acceleration limits), so plans, previews and the driver
agree. Captures are placed by forward kinematics of the arm's reported joints and the plate angle.

Source (``POST /api/sessions``): ``{"kind": "hardware", "dry_run": false, "truth": null}``. Requests never
name a path: the server's cell file is used, and the journal header records it (``cell``), so a resumed
session reopens the same devices. ``truth``: a model name whose surface measures coverage (a known test
object on the plate); without it a hardware session has no coverage.

Safety:

- A real arm moves only on an approval: ``step`` and ``auto`` are refused (409) unless the cell file says
  ``allow_auto = true`` (:func:`auto_refusal`; also in a dry run, which rehearses the same scan).
- ``dry_run`` (or ``nbv serve --dry-run``): no device is opened; the cell is the simulator with the cell
  file's arm model, scanning the session's model.
- ``POST /api/sessions/{id}/stop``: :func:`stop_devices` stops the arm and the turntable at once (each
  driver's ``stop()``) when a move is running; the move ends with a DeviceError naming the arm's last joints,
  and the session goes to its error state with that message journaled.
- One live session holds a cell file's devices at a time (a second one is refused with 409).
"""

from __future__ import annotations

import dataclasses
import math
import threading
import time
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np
import trimesh

from devices.cell import Cell, Motion
from devices.cellfile import CellFile, load_cell_file
from devices.config import CameraConfig, CellConfig
from devices.hwcell import arm_cell_config
from devices.protocols import DeviceError
from planner.types import Pose
from workbench.errors import Conflict, Invalid

if TYPE_CHECKING:
    from devices.arm.kinematics import ArmKinematics
    from devices.rig import Rig
    from workbench.session.session import Session

SOURCE_KEYS = ("kind", "dry_run", "truth", "cell", "mode")
"""Keys of a hardware source (``mode``, a replay setting the API always sends, is ignored)."""
STOP_WAIT = 5.0
"""How long ``stop`` waits for a halted move to end (the session then shows its error state), seconds."""

_in_use: dict[str, str] = {}
"""Cell files whose devices an open HardwareCell holds: resolved path -> label of the holder."""
_in_use_lock = threading.Lock()


def arm_kinematics(cell: CellFile, config: CellConfig) -> tuple[CellConfig, ArmKinematics]:
    """(config, its arm model) with planned joint speeds within the cell file's ``max_joint_speed_deg``: the
    arm's ``velocity_scale`` is lowered when the URDF's limits times the scale would exceed it."""
    from devices.arm.kinematics import ArmKinematics

    kinematics = ArmKinematics(config.arm, config.plate_radius, config.plate_thickness)
    limit = getattr(cell.arm.config, "max_joint_speed_deg", None) if cell.arm is not None else None
    fastest = float(np.max(kinematics.model.velocity))
    if limit is not None and fastest > math.radians(limit):
        scale = config.arm.velocity_scale * math.radians(limit) / fastest * 0.999
        config = dataclasses.replace(config, arm=dataclasses.replace(config.arm, velocity_scale=scale))
        kinematics = ArmKinematics(config.arm, config.plate_radius, config.plate_thickness)
    return config, kinematics


class HardwareCell(Cell):
    """A :class:`Cell` on a cell file's devices (``rig``), or, in a dry run, on simulated devices.

    cellfile: the parsed cell file (``allow_auto``, hand-eye, mount). rig: the opened devices (None in a dry
    run). holder: the key of this cell's claim on the devices (released by :meth:`close`).
    """

    def __init__(
        self,
        camera: Any,
        arm: Any,
        turntable: Any,
        config: CellConfig,
        *,
        kinematics: ArmKinematics,
        cellfile: CellFile,
        rig: Rig | None,
        holder: str = "",
        **kwargs: Any,
    ) -> None:
        super().__init__(camera, arm, turntable, config, kinematics=kinematics, **kwargs)
        self.cellfile = cellfile
        self.rig = rig
        self.holder = holder
        self.moving = threading.Event()
        self.stop_requested = threading.Event()
        self._closed = False

    @property
    def dry_run(self) -> bool:
        return self.rig is None

    @property
    def allow_auto(self) -> bool:
        return self.cellfile.allow_auto

    def arm_state(self) -> str:
        """The arm's joints in degrees, or why they cannot be read (for error messages)."""
        try:
            q = self.arm.joint_positions()
        except DeviceError as exc:
            last = getattr(self.arm, "last_joint_positions", None)
            if last is None:
                return f"arm joints unknown ({exc})"
            q = last
        return "arm at joints [" + ", ".join(f"{math.degrees(float(v)):.2f}" for v in q) + "] deg"

    def move_to(self, T_table_camera: Pose) -> Motion:
        """:meth:`Cell.move_to`; a DeviceError (a fault, a refused trajectory, a stop) names the arm's last joints."""
        self.stop_requested.clear()
        self.moving.set()
        try:
            motion = super().move_to(T_table_camera)
            if self.stop_requested.is_set():
                raise DeviceError("stopped on request")
            return motion
        except DeviceError as exc:
            message = str(exc)
            if "last joints" not in message:
                message = f"{message}; {self.arm_state()}"
            exc.args = (message,)  # the same type and fields (ArmFaultError.joint_positions), a fuller message
            raise
        finally:
            self.moving.clear()

    def halt(self) -> list[str]:
        """Stop the arm and the turntable at once if a move is running; returns the drivers' errors."""
        if not self.moving.is_set():
            return []
        self.stop_requested.set()
        if self.rig is not None:
            return self.rig.stop()
        for device in (self.arm, self.turntable):
            stop = getattr(device, "stop", None)
            if callable(stop):
                stop()
        return []

    def restore_device_state(self, state: dict[str, Any]) -> None:
        """A resumed session on real devices moves nothing: the next plan starts from where they really are."""
        if self.dry_run:
            super().restore_device_state(state)

    def close(self) -> None:
        """Close the devices (once) and release the claim on them."""
        if self._closed:
            return
        self._closed = True
        try:
            if self.rig is not None:
                self.rig.close()
        finally:
            with _in_use_lock:
                _in_use.pop(self.holder, None)


def auto_refusal(cell: Cell) -> str | None:
    """Why ``step`` / ``auto`` may not run on this cell (None: they may)."""
    if isinstance(cell, HardwareCell) and not cell.allow_auto:
        where = cell.cellfile.source or "the cell file"
        return (
            "step and auto mode would move the arm without an approval per view; "
            f"{where} does not allow it (set devices.allow_auto = true)"
        )
    return None


def stop_devices(session: Session, wait: float = STOP_WAIT) -> list[str]:
    """Stop the arm and the turntable of ``session`` at once if a move is running, then wait up to ``wait`` s
    for the session to leave its busy state (it goes to error). Returns the drivers' errors."""
    from workbench.session.values import BUSY

    cell = session.cell
    if not isinstance(cell, HardwareCell):
        return []
    errors = cell.halt()
    deadline = time.monotonic() + wait
    while session.state in BUSY and cell.stop_requested.is_set() and time.monotonic() < deadline:
        time.sleep(0.01)
    return errors


def hardware_source(settings: Any, source: dict[str, Any]) -> dict[str, Any]:
    """The journaled form of a ``hardware`` source: ``cell`` (the server's cell file), ``dry_run``, ``truth``.
    Invalid for unknown keys, a server without a cell file, or another cell file than the server's."""
    for key in source:
        if key not in SOURCE_KEYS:
            raise Invalid(f"source.{key}: unknown setting (known: {', '.join(SOURCE_KEYS)})")
    if not settings.cell:
        raise Invalid("source.kind: 'hardware' needs a cell file (nbv serve --cell cell.toml, or [server] cell)")
    given = source.get("cell")
    if given is not None and str(given) != settings.cell:
        raise Invalid(f"source.cell: this session used the cell file {given!r}; the server uses {settings.cell!r}")
    dry_run = source.get("dry_run") or False
    if not isinstance(dry_run, bool):
        raise Invalid(f"source.dry_run: expected true/false, got {dry_run!r}")
    truth = source.get("truth")
    if truth is not None and not isinstance(truth, str):
        raise Invalid(f"source.truth: a model name or null, got {truth!r}")
    return {"kind": "hardware", "cell": settings.cell, "dry_run": dry_run or settings.dry_run, "truth": truth}


def read_cell_file(path: str) -> CellFile:
    """The server's cell file; Invalid (one line naming the field) when it is bad."""
    try:
        return load_cell_file(path)
    except ValueError as exc:
        raise Invalid(str(exc)) from None


def _claim(path: str, label: str) -> str:
    key = str(Path(path).resolve())
    with _in_use_lock:
        if key in _in_use:
            raise Conflict(f"the devices of {path} are in use by {_in_use[key]}; delete or stop it first")
        _in_use[key] = label
    return key


def hardware_cell(
    source: dict[str, Any],
    mesh: trimesh.Trimesh | None,
    camera: CameraConfig,
    base: CellConfig,
    seed: int,
) -> HardwareCell:
    """The cell of a ``hardware`` source (from :func:`hardware_source`). A dry run simulates ``mesh`` with
    ``camera``; otherwise the cell file's devices are opened (409 when another session holds them, 503 when
    a device cannot be opened, 422 for a bad cell file)."""
    from devices.rig import open_rig
    from workbench.errors import DeviceFault

    cellfile = read_cell_file(source["cell"])
    try:
        config, kinematics = arm_kinematics(cellfile, arm_cell_config(cellfile, base))
    except ValueError as exc:
        message = str(exc)
        for prefix in ("cell.arm.base:", "arm.base:"):  # the arm model's mount is the cell file's arm_base
            if message.startswith(prefix):
                message = "devices.arm_base:" + message.removeprefix(prefix)
        raise Invalid(message) from None
    if source["dry_run"]:
        from devices.sim import make_sim_cell

        sim = make_sim_cell(mesh, camera, config, seed=seed)
        assert sim.kinematics is not None
        return HardwareCell(
            sim.camera,
            sim.arm,
            sim.turntable,
            config,
            kinematics=sim.kinematics,
            cellfile=cellfile,
            rig=None,
            pose_noise_translation=camera.pose_noise_translation,
            pose_noise_rotation_deg=camera.pose_noise_rotation_deg,
            seed=seed,
        )
    missing = [kind for kind in ("camera", "arm", "turntable") if getattr(cellfile, kind) is None]
    if missing:
        raise Invalid(f"devices.{missing[0]}: a hardware session needs a camera, an arm and a turntable")
    holder = _claim(source["cell"], "a live session")
    try:
        rig = open_rig(cellfile)
    except (DeviceError, OSError) as exc:
        with _in_use_lock:
            _in_use.pop(holder, None)
        raise DeviceFault(f"cannot open the devices of {source['cell']}: {exc}") from None
    except BaseException:
        with _in_use_lock:
            _in_use.pop(holder, None)
        raise
    try:
        return HardwareCell(
            rig.camera, rig.arm, rig.turntable, config, kinematics=kinematics, cellfile=cellfile, rig=rig, holder=holder
        )
    except BaseException:
        rig.close()
        with _in_use_lock:
            _in_use.pop(holder, None)
        raise
