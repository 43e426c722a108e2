"""What a new (or resumed) session is made of: the object, the cell (simulated or replay), the faults.

Sources (the ``source`` of a create request):

- ``{"kind": "sim"}`` (default): the model on the simulated cell.
- ``{"kind": "replay", "recording": NAME, "mode": "sequence" | "nearest"}``: a recording folder
  ``data_dir/recordings/NAME`` (PLY + pose JSON per view, docs/journal.md).
  A recording may also be a ROS 2 bag there: ``NAME.mcap``, ``NAME.db3`` or a rosbag2 folder (devices/rosbag.py;
  ``"topics": {"depth", "camera_info", "joint_states", "plate_frame"}`` names where its scan is, docs/bags.md).
- ``{"kind": "replay", "session": ID, "mode": ...}``: the frames of a journaled session.
- ``{"kind": "recorded", "recorded": NAME}``: a recorded view set ``data_dir/recorded/NAME`` (a ``views.json``
  folder or Stanford range scans, docs/real-data.md): its views are the only candidates, its reference mesh (or
  the union of its views) the ground truth.
- ``{"kind": "hardware", "dry_run": false, "truth": null}``: the devices of the server's cell file
  (workbench/sources/hardware.py); the default source when the server has one (``nbv serve --cell``).

Requests name recordings and sessions; they never give a path. A name is looked
up among the folders that exist (:func:`list_recordings`), so ``../``, absolute
paths and symlinks leading out of the data directory find nothing.
"""

from __future__ import annotations

import contextlib
import dataclasses
import logging
import re
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
import trimesh
from numpy.typing import NDArray

from devices.cell import Cell
from devices.config import DeviceConfig
from devices.faults import FaultConfig, FaultInjector, with_faults
from planner import DepthFrame
from workbench.errors import Invalid, NotFound
from workbench.journal.store import SESSION_ID, list_journals, read_journal
from workbench.settings import WorkbenchSettings
from workbench.sources.catalog import find_model, load_model

SURFACE_SAMPLES = 10_000
"""Points sampled on the ground-truth mesh to measure coverage (simulation only)."""
RECORDING_NAME = re.compile(r"^[A-Za-z0-9][A-Za-z0-9_.-]{0,63}$")

log = logging.getLogger(__name__)


@dataclass(eq=False)
class SessionParts:
    """The object and devices of a session. ``mesh`` is empty and ``surface_samples`` None without ground truth."""

    model: str
    model_kind: str
    mesh: trimesh.Trimesh
    cell: Cell
    surface_samples: NDArray[np.float64] | None
    source: dict[str, Any]
    injector: FaultInjector | None
    """Decides the simulated faults of the devices; None for real hardware (never injected there)."""
    noise_model: str = "ideal"
    """Real hardware: the sensor model the planner assumes for the cell's camera (its cell file's
    ``noise_model``, ``HardwareCell.noise_model``); the other sources simulate their camera's own."""


def recordings_dir(settings: WorkbenchSettings) -> Path:
    return settings.data_dir / "recordings"


def list_recordings(settings: WorkbenchSettings) -> list[str]:
    """Names of the recording folders and ROS 2 bag files (``.mcap``, ``.db3``) directly inside
    ``data_dir/recordings`` (no symlinks, no dot names)."""
    from devices.rosbag import BAG_SUFFIXES

    root = recordings_dir(settings)
    if not root.is_dir():
        return []
    return sorted(
        p.name
        for p in root.iterdir()
        if RECORDING_NAME.match(p.name)
        and not p.is_symlink()
        and (p.is_dir() or (p.is_file() and p.suffix in BAG_SUFFIXES))
    )


def bag_frames(path: Path, topics: dict[str, Any] | None) -> tuple[list[DepthFrame], str | None]:
    """(frames, ground-truth model name or None) of the ROS 2 bag at ``path``: the truth is the model of a
    simulated session the bag was exported from (its ``/nbv/scan``). ValueError for a bad bag or bad topics."""
    from devices.rosbag import BagTopics, load_bag

    try:
        import rosbags  # noqa: F401
    except ImportError:
        raise ValueError("a ROS 2 bag needs rosbags: pip install 'nbv-workbench[ros2]'") from None
    scan = load_bag(path, BagTopics.from_dict(topics))
    model, source = scan.info.get("model"), scan.info.get("source")
    sim = isinstance(source, dict) and source.get("kind") == "sim"
    truth = model.get("name") if sim and isinstance(model, dict) and isinstance(model.get("name"), str) else None
    return list(scan.frames), truth


def recorded_dir(settings: WorkbenchSettings) -> Path:
    return settings.data_dir / "recorded"


def list_recorded(settings: WorkbenchSettings) -> list[str]:
    """Names of the recorded view sets directly inside ``data_dir/recorded`` (no symlinks, no dot names)."""
    root = recorded_dir(settings)
    if not root.is_dir():
        return []
    return sorted(p.name for p in root.iterdir() if RECORDING_NAME.match(p.name) and p.is_dir() and not p.is_symlink())


def recorded_parts(settings: WorkbenchSettings, source: dict[str, Any], seed: int) -> tuple[Any, Any, Any]:
    """(the recorded set, its truth mesh (empty without a reference), surface samples) of a recorded source.
    404 for an unknown name, 422 for a set that cannot be read."""
    from devices.mesh import sample_surface
    from devices.recorded import read_recorded

    name = str(source.get("recorded") or "")
    if name not in list_recorded(settings):  # a lookup among what exists, never a path join
        known = ", ".join(list_recorded(settings)) or "none"
        raise NotFound(f"recorded set {name!r}: unknown (known: {known})")
    try:
        recorded = read_recorded(recorded_dir(settings) / name)
    except ValueError as exc:
        raise Invalid(f"recorded set {name!r}: {str(exc).replace(str(settings.data_dir), '<data>')}") from None
    if recorded.reference is not None:
        return recorded, recorded.reference, sample_surface(recorded.reference, SURFACE_SAMPLES, seed=seed)
    union = recorded.union_world()
    pick = np.random.default_rng(seed).choice(len(union), size=min(SURFACE_SAMPLES, len(union)), replace=False)
    return recorded, trimesh.Trimesh(), union[pick]


def ground_truth(
    settings: WorkbenchSettings, name: str, seed: int, stage: Callable[[str], None] = lambda name: None
) -> tuple[trimesh.Trimesh, NDArray[np.float64]]:
    """The mesh of model ``name`` and ``SURFACE_SAMPLES`` points on it (seeded). NotFound / Invalid.
    stage: told each stage as it starts."""
    from devices.mesh import sample_surface

    mesh = load_model(settings, name, stage)
    stage("sampling its surface")
    try:
        return mesh, sample_surface(mesh, SURFACE_SAMPLES, seed=seed)
    except ValueError as exc:
        raise Invalid(f"model {name!r}: {exc}") from None


def replay_frames(settings: WorkbenchSettings, source: dict[str, Any]) -> tuple[list[DepthFrame], str, str | None]:
    """(frames, label, ground-truth model name or None) of a replay source. 404 unknown name, 422 bad data."""
    from devices.replay import load_recording

    if source.get("recording") is not None:
        name = str(source["recording"])
        if name not in list_recordings(settings):  # a lookup among what exists, never a path join
            known = ", ".join(list_recordings(settings)) or "none"
            raise NotFound(f"recording {name!r}: unknown (known: {known})")
        try:
            from devices.rosbag import is_bag

            path = recordings_dir(settings) / name
            if is_bag(path):
                frames, truth = bag_frames(path, source.get("topics"))
                return frames, f"replay:{name}", truth
            if source.get("topics"):
                raise ValueError("'topics' are for a ROS 2 bag; this is a folder of PLY + JSON views")
            return load_recording(path), f"replay:{name}", None
        except ValueError as exc:
            raise Invalid(f"recording {name!r}: {str(exc).replace(str(settings.data_dir), '<data>')}") from None
    session = str(source.get("session") or "")
    folders = {p.name: p for p in list_journals(settings.data_dir)} if SESSION_ID.match(session) else {}
    if session not in folders:
        raise NotFound(f"journaled session {session!r}: unknown")
    try:
        journal = read_journal(folders[session])
        frames = [journal.frame(e) for e in journal.of_kind("capture") if e.get("frame")]
    except ValueError as exc:
        raise Invalid(f"journaled session {session!r}: {exc}") from None
    if not frames:
        raise Invalid(f"journaled session {session!r}: no frame to replay")
    truth = journal.header.get("model", {}).get("name")
    return frames, f"replay:{session}", truth if journal.header.get("source", {}).get("kind") == "sim" else None


def build_parts(
    settings: WorkbenchSettings,
    model: str | None,
    source: dict[str, Any] | None,
    seed: int,
    devices: DeviceConfig,
    faults: FaultConfig,
    stage: Callable[[str], None] = lambda name: None,
    faults_asked: bool = False,
    camera_asked: bool = False,
) -> SessionParts:
    """The object and the (fault-injecting) devices of a session. 404/422 with a clear message on bad input.

    stage: told each stage as it starts (``workbench.progress.CREATE_STAGES``); it may raise to cancel.
    Simulated faults are never injected into real hardware: ``faults`` asked by the request
    (``faults_asked``) are refused for it (422), the server's ``[faults]`` are left out with a warning; so is a
    simulated sensor or calibration error the request asked for (``camera_asked``)."""
    from devices.sim import make_sim_cell

    source = dict(source or {"kind": "hardware" if settings.cell else "sim"})
    kind = source.get("kind", "sim")
    if kind == "sim":
        name = model or settings.devices.model
        try:
            info = find_model(settings, name)
        except NotFound as exc:  # a bad parameter of this request, not an unknown resource
            raise Invalid(exc.detail) from None
        mesh, samples = ground_truth(settings, name, seed, stage)
        stage("building the cell")
        try:
            cell = make_sim_cell(mesh, devices.camera, devices.cell, seed=seed)
        except ValueError as exc:
            raise Invalid(f"model {name!r}: {exc}") from None
        model_kind = info.kind
    elif kind == "replay":
        from devices.replay import ReplayCell

        frames, name, truth = replay_frames(settings, source)
        mesh, samples = trimesh.Trimesh(), None
        if truth is not None:
            with contextlib.suppress(NotFound, Invalid):  # gone: no coverage, the replay still works
                mesh, samples = ground_truth(settings, truth, seed)
        stage("building the cell")
        try:
            cell = ReplayCell(frames, devices.cell, source.get("mode", "sequence"))
        except ValueError as exc:
            raise Invalid(f"{name}: {exc}") from None
        model_kind = "replay"
    elif kind == "recorded":
        from devices.recorded import RecordedCell

        recorded, mesh, samples = recorded_parts(settings, source, seed)
        stage("building the cell")
        cell = RecordedCell(recorded, devices.cell)
        name, model_kind = f"recorded:{source['recorded']}", "recorded"
    elif kind == "hardware":
        from workbench.sources.hardware import hardware_cell, hardware_source

        source = hardware_source(settings, source)
        truth = source["truth"] or (model or settings.devices.model if source["dry_run"] else None)
        mesh, samples = trimesh.Trimesh(), None
        if truth is not None:
            try:
                find_model(settings, truth)
            except NotFound as exc:
                raise Invalid(f"source.truth: {exc.detail}") from None
            mesh, samples = ground_truth(settings, truth, seed)
        if not source["dry_run"] and camera_asked:
            raise Invalid(
                "camera: a simulated sensor or calibration error goes into the simulated camera only; this session "
                "drives the real camera of the cell file, which has its own noise"
            )
        if not source["dry_run"] and faults.enabled:
            if faults_asked:
                raise Invalid(
                    "faults: simulated faults go into simulated devices only; this session drives the real devices "
                    'of the cell file (a dry run, source {"dry_run": true}, rehearses with faults)'
                )
            log.warning("the server's [faults] are not injected into the real devices of %s", source["cell"])
        stage("building the cell")
        cell = hardware_cell(source, mesh if source["dry_run"] else None, devices.camera, devices.cell, seed)
        name, model_kind = truth or f"hardware:{Path(source['cell']).stem}", "hardware"
        if not source["dry_run"]:
            return SessionParts(name, model_kind, mesh, cell, samples, source, None, cell.noise_model)
    else:
        raise Invalid(f"source.kind: 'sim', 'replay', 'hardware' or 'recorded', got {kind!r}")
    injector = FaultInjector(faults)
    with_faults(cell, injector)
    return SessionParts(name, model_kind, mesh, cell, samples, source, injector)


def arm_choices() -> list[dict[str, Any]]:
    """The arms a create request may name (the arms resource lists them): every preset, then 'reach_sphere'."""
    from devices.arm.presets import DEFAULT_PRESET, PRESETS

    arms: list[dict[str, Any]] = [
        {"name": p.name, "title": p.title, "dof": p.dof, "default": p.name == DEFAULT_PRESET, "note": p.note}
        for p in PRESETS.values()
    ]
    arms.append({"name": "reach_sphere", "title": "reach sphere (no arm model)", "dof": 0, "default": False,
                 "note": "the camera goes wherever it is within the reach sphere"})  # fmt: skip
    return arms


def check_arm_name(arm: str | None) -> str | None:
    """A create request's ``arm``: None, a preset or 'reach_sphere' (not a file: a client names no server path);
    Invalid listing them otherwise."""
    if arm is None:
        return None
    known = [a["name"] for a in arm_choices()]
    if arm not in known:
        raise Invalid(f"arm: unknown arm {arm!r} (known: {', '.join(known)})")
    return arm


def session_devices(
    settings: WorkbenchSettings,
    model: str,
    seed: int,
    camera: dict[str, str] | None = None,
    arm: str | None = None,
    move_capture: float | None = None,
) -> DeviceConfig:
    """The server's device config for one session: its model and seed, the ``camera`` models it asked for
    (``{"sensor", "calibration"}``, checked by ``workbench.sources.camera_models.check_camera_models``), the
    ``arm`` (a preset or 'reach_sphere', :func:`check_arm_name`; None = the server's) and the rate of capture
    during moves (``move_capture`` frames per second; None = the server's ``devices.cell.move_capture_hz``)."""
    from devices.config import cell_with_arm

    devices = dataclasses.replace(settings.devices, model=model, seed=seed)
    if arm is not None:
        devices = dataclasses.replace(devices, cell=cell_with_arm(devices.cell, arm))
    if move_capture is not None:
        devices = dataclasses.replace(
            devices, cell=dataclasses.replace(devices.cell, move_capture_hz=float(move_capture))
        )
    if camera:
        devices = dataclasses.replace(devices, camera=dataclasses.replace(devices.camera, **camera))
    return devices
