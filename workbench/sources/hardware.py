"""The ``hardware`` session source: a supervised scan on the devices of a cell file, and its safety rules.

``nbv serve --cell cell.toml`` (or ``[server] cell = "cell.toml"``) makes ``hardware`` the default source of a
new session. This module reads the request (:func:`hardware_source`) and asks devices/hwcell.py for the cell:
a :class:`devices.hwcell.HardwareCell`, the rig's camera, arm and turntable with the arm model configured from
the cell file (hand-eye transform, mount, joint limits and names, speed and acceleration limits), so plans,
previews and the driver agree. Captures are placed by forward kinematics of the arm's reported joints and the
plate angle; the device errors become domain errors here.

Source (of a create request): ``{"kind": "hardware", "dry_run": false, "truth": null}``. Requests never
name a path: the server's cell file is used, and the journal header records it (``cell``), so a resumed
session reopens the same devices. ``truth``: a model name whose surface measures coverage (a known test
object on the plate); without it a hardware session has no coverage.

Safety:

- A real arm moves only on an approval: ``step`` and ``auto`` are refused (409) unless the cell file says
  ``allow_auto = true`` (``HardwareCell.auto_refusal``; also in a dry run, which rehearses the same scan).
- ``dry_run`` (or ``nbv serve --dry-run``): no device is opened; the cell is the simulator with the cell
  file's arm model, scanning the session's model.
- Stop (``Session.stop``) halts the arm and the turntable at once (each driver's ``stop()``) when a move is
  running; the move ends with a DeviceError naming the arm's last joints, and the session goes to its error
  state with that message journaled.
- One live session holds a cell file's devices at a time (a second one is refused with 409).
"""

from __future__ import annotations

from typing import Any

import trimesh

from devices.cellfile import CellFile, load_cell_file
from devices.config import CameraConfig, CellConfig
from devices.hwcell import DevicesInUse, HardwareCell, dry_run_cell, open_hardware_cell
from devices.protocols import DeviceError
from workbench.errors import Conflict, DeviceFault, Invalid

SOURCE_KEYS = ("kind", "dry_run", "truth", "cell", "mode")
"""Keys of a hardware source (``mode``, a replay setting the API always sends, is ignored)."""


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


def _invalid(exc: ValueError) -> Invalid:
    message = str(exc)
    for prefix in ("cell.arm.base:", "arm.base:"):  # the arm model's mount is the cell file's arm_base
        if message.startswith(prefix):
            message = "devices.arm_base:" + message.removeprefix(prefix)
    return Invalid(message)


def hardware_cell(
    source: dict[str, Any],
    mesh: trimesh.Trimesh | None,
    camera: CameraConfig,
    base: CellConfig,
    seed: int,
    label: str = "a live session",
) -> HardwareCell:
    """The cell of a ``hardware`` source (from :func:`hardware_source`). A dry run simulates ``mesh`` with
    ``camera``; otherwise the cell file's devices are opened (409 when another session holds them, 503 when
    a device cannot be opened, 422 for a bad cell file). label: who holds the devices (named to a second holder)."""
    cellfile = read_cell_file(source["cell"])
    try:
        if source["dry_run"]:
            return dry_run_cell(cellfile, base, mesh, camera, seed)
        return open_hardware_cell(cellfile, base, label)
    except ValueError as exc:
        raise _invalid(exc) from None
    except DevicesInUse as exc:
        raise Conflict(str(exc)) from None
    except (DeviceError, OSError) as exc:
        raise DeviceFault(f"cannot open the devices of {source['cell']}: {exc}") from None
