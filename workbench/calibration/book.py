"""The calibrations a server runs: each on its own cell, simulated or the server's hardware (its cell file).

A create request is one of:

- ``{"kind": "sim", "sensor": "realsense-d435", "calibration": "poor", "seed": 0}``: a simulated cell with the
  target on its plate and the calibration error model named (drawn from the seed); its status compares the
  estimate with the drawn truth. Nothing to write.
- ``{"kind": "hardware", "dry_run": false}``: the devices of the server's cell file (``nbv serve --cell``), held
  by the calibration until it is closed (a live session on the same devices is refused meanwhile, and the other
  way round). ``dry_run`` (or ``nbv serve --dry-run``): the simulator on the cell file's arm model; nothing opens
  or moves, and nothing is written.

Both may give ``plate_angles_deg`` (a list, default the routine's six) and ``views`` (the first 1..6 views per
plate angle of devices/calibration/poses.py, default all): fewer poses for a quick rehearsal.
"""

from __future__ import annotations

import logging
import math
import secrets
import threading
from typing import Any

from devices.calibration import DEFAULT_TARGET, Calibration, CalibrationError, calibration_poses, sim_truth
from devices.calibration.poses import PLATE_ANGLES_DEG, VIEWS
from devices.protocols import DeviceError
from workbench.calibration.journal import CalibrationJournal, read_calibrations
from workbench.calibration.run import CalibrationRun
from workbench.errors import Conflict, Invalid, NotFound, StorageFault, WorkbenchError
from workbench.settings import WorkbenchSettings
from workbench.sources.camera_models import check_camera_models
from workbench.sources.hardware import hardware_cell, hardware_source

log = logging.getLogger(__name__)

MAX_CALIBRATIONS = 4
"""Calibrations open at once (each holds a cell; close one to start another)."""
KEYS = ("kind", "sensor", "calibration", "seed", "dry_run", "plate_angles_deg", "views")


def _poses_of(request: dict[str, Any]) -> tuple[tuple[float, ...], int]:
    angles = request.get("plate_angles_deg")
    if angles is None:
        angles = PLATE_ANGLES_DEG
    if not isinstance(angles, list | tuple) or not angles or len(angles) > 12:
        raise Invalid(f"plate_angles_deg: a list of 1 to 12 angles in degrees, got {angles!r}")
    if not all(isinstance(a, int | float) and not isinstance(a, bool) and math.isfinite(a) for a in angles):
        raise Invalid(f"plate_angles_deg: finite numbers, got {angles!r}")
    views = request.get("views", len(VIEWS))
    if not isinstance(views, int) or isinstance(views, bool) or not 1 <= views <= len(VIEWS):
        raise Invalid(f"views: an integer in 1..{len(VIEWS)}, got {views!r}")
    return tuple(float(a) for a in angles), views


class Calibrations:
    """The open calibrations of a server with ``settings`` (thread-safe)."""

    def __init__(self, settings: WorkbenchSettings) -> None:
        self.settings = settings
        self._lock = threading.Lock()
        self._runs: dict[str, CalibrationRun] = {}
        if settings.journal:
            self._restore()

    def _restore(self) -> None:
        """Rebuild the calibrations journaled by an earlier server (workbench/calibration/journal.py): the same
        cell from the same request, the same pose outcomes, the estimate redone. One that cannot be rebuilt now
        (its devices do not open) is logged and its journal kept for the next start."""
        for entry in read_calibrations(self.settings.data_dir):
            try:
                run = self._build(entry.request, entry.id)
                run.restore(entry.events)
            except (WorkbenchError, CalibrationError, DeviceError, OSError, ValueError, KeyError, TypeError) as exc:
                log.warning("calibration %s: not restored from its journal: %s", entry.id, exc)
                continue
            run.journal = CalibrationJournal(entry.directory or self.settings.data_dir)
            with self._lock:
                self._runs[run.id] = run
            log.info("calibration %s restored from its journal (%d outcomes)", run.id, len(entry.events))

    def get(self, calibration_id: str) -> CalibrationRun:
        with self._lock:
            run = self._runs.get(calibration_id)
        if run is None:
            raise NotFound(f"calibration {calibration_id}: unknown (closed, or from an earlier server)")
        return run

    def list(self) -> list[CalibrationRun]:
        with self._lock:
            return list(self._runs.values())

    def create(self, request: dict[str, Any]) -> CalibrationRun:
        """A new calibration (see the module docstring), journaled (a restart keeps it); Invalid for a bad request,
        Conflict when too many are open or another holder has the devices, DeviceFault when a device cannot be
        opened, StorageFault when it cannot be journaled."""
        run = self._build(request, f"cal-{secrets.token_hex(4)}")
        if self.settings.journal:
            try:
                run.journal = CalibrationJournal.create(self.settings.data_dir, run.id, dict(request))
            except (OSError, TypeError, ValueError) as exc:
                run.close()
                raise StorageFault(f"calibration: cannot journal it in the data directory ({exc})") from None
        with self._lock:
            self._runs[run.id] = run
        return run

    def _build(self, request: dict[str, Any], calibration_id: str) -> CalibrationRun:
        """The calibration of ``request`` under ``calibration_id`` (not registered yet)."""
        unknown = sorted(set(request) - set(KEYS))
        if unknown:
            raise Invalid(f"calibration: unknown field(s) {', '.join(unknown)} (known: {', '.join(KEYS)})")
        kind = request.get("kind", "hardware" if self.settings.cell else "sim")
        seed = request.get("seed", 0)
        if not isinstance(seed, int) or isinstance(seed, bool) or seed < 0:
            raise Invalid(f"seed: a non-negative integer, got {seed!r}")
        angles, views = _poses_of(request)
        with self._lock:
            if len(self._runs) >= MAX_CALIBRATIONS:
                raise Conflict(f"{MAX_CALIBRATIONS} calibrations are open: close one first")
        truth, cell_file = None, None
        if kind == "sim":
            if request.get("dry_run"):
                raise Invalid("dry_run: only for kind 'hardware' (a simulated cell moves nothing anyway)")
            camera = check_camera_models({k: request[k] for k in ("sensor", "calibration") if k in request}) or {}
            from devices.calibration import calibration_sim_cell

            cell = calibration_sim_cell(camera.get("sensor", "realsense-d435"), camera.get("calibration", "poor"), seed)
            truth = sim_truth(cell)
            source: dict[str, Any] = {"kind": "sim", "sensor": "realsense-d435", "calibration": "poor", **camera}
            source["seed"] = seed
        elif kind == "hardware":
            if "sensor" in request or "calibration" in request:
                raise Invalid("sensor, calibration: simulated cells only (a real camera has its own noise)")
            source = hardware_source(self.settings, {"kind": "hardware", "dry_run": request.get("dry_run", False)})
            cell = hardware_cell(
                source, DEFAULT_TARGET.mesh(), self.settings.devices.camera, self.settings.devices.cell, seed,
                label="a calibration",
            )  # fmt: skip
            cell_file = None if source["dry_run"] else source["cell"]
        else:
            raise Invalid(f"kind: 'sim' or 'hardware', got {kind!r}")
        try:
            if cell.kinematics is None:
                raise CalibrationError("calibration: the cell has no arm model (cell.kinematics = 'urdf' is needed)")
            mount = cell.kinematics.model.T_base_mount.translation
            poses = calibration_poses(DEFAULT_TARGET, math.atan2(mount[1], mount[0]), angles, VIEWS[:views])
            routine = Calibration(cell, DEFAULT_TARGET, poses)
        except CalibrationError as exc:
            cell.close()
            raise Invalid(str(exc)) from None
        source.update(plate_angles_deg=list(angles), views=views)
        return CalibrationRun(calibration_id, routine, source, cell_file, truth, self.settings.move_timeout)

    def close(self, calibration_id: str) -> None:
        """Close a calibration and release its cell (NotFound when unknown; Conflict while it moves)."""
        run = self.get(calibration_id)
        if run.status()["busy"]:
            raise Conflict(f"calibration {calibration_id}: busy; close it when the move has ended")
        with self._lock:
            self._runs.pop(calibration_id, None)
        run.close()
        if run.journal is not None:
            run.journal.delete()

    def close_all(self) -> None:
        with self._lock:
            runs, self._runs = list(self._runs.values()), {}
        for run in runs:
            run.close()
