"""What the workbench needs to run sessions: where models and journals live, limits, timeouts, defaults.

``WorkbenchSettings`` is frozen and knows no server: the web app's ``AppSettings`` (app/settings.py)
extends it with where it listens, so ``[server] data_dir = ...`` in a TOML file reaches the same field.
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from devices.config import DeviceConfig
from devices.faults import FaultConfig
from planner.config import PlannerConfig
from planner.validate import finite, integer
from workbench.sources.limits import MeshLimits
from workbench.surface.scoring import SURFACE_SAMPLES


def default_models_dir() -> Path:
    """``../shared/models`` when it exists (the team's test meshes), else ``./models``."""
    shared = Path("../shared/models")
    return shared if shared.is_dir() else Path("models")


MIN_SCORE_POINTS = 1_000
MAX_SCORE_POINTS = 1_000_000
"""The range of ``surface_score_points``: a million points are 24 MB of coordinates and about ten times the
default's CPU a view."""


@dataclass(frozen=True)
class WorkbenchSettings:
    """Where the sessions' files live and how the sessions run. Paths are resolved when used, not here."""

    models_dir: Path = field(default_factory=default_models_dir)
    """Directory of mesh files offered as models (.obj, .ply, .stl, .off, .glb)."""
    data_dir: Path = Path("nbv-data")
    """Where uploads (``uploads/``), session journals (``sessions/``) and replay recordings
    (``recordings/``) live. See docs/journal.md."""
    max_upload_bytes: int = 50 * 1024 * 1024
    """Uploads larger than this are refused (413)."""
    capture_timeout: float = 30.0
    """A capture that takes longer fails with a timeout (the session goes to state error), seconds."""
    move_timeout: float = 120.0
    """A cell move (turntable + arm) that takes longer fails with a timeout, seconds."""
    plan_budget: float = 60.0
    """A plan (BIC fits, scoring) that takes longer is killed in its worker process; the session goes to state
    error with the reason, the map unchanged, seconds (0: no limit)."""
    capture_budget: float = 30.0
    """Capturing and integrating one view (ray casting, preprocessing, ICP, the voxel map) that takes longer
    is killed in its worker process like a plan, seconds (0: no limit). The move before it has move_timeout."""
    workers: bool = True
    """Run each live session's heavy work (rendering, integration, fitting, scoring) in a worker process that
    can be killed (workbench/workers/pool.py); False: in the server process (tests of the state machine alone)."""
    max_running_jobs: int = 0
    """Heavy jobs running at once over all sessions (others wait their turn); 0: os.cpu_count()."""
    max_idle_workers: int = 4
    """Worker processes kept for idle sessions; beyond this the least recently used is stopped (rebuilt from
    the journal when its session works again)."""
    mesh_limits: MeshLimits = field(default_factory=MeshLimits)
    """What a model mesh may cost (triangles, vertices, polygon degree, triangles per vertex): workbench/sources/limits.py."""
    max_live_sessions: int = 16
    """Sessions live in memory at once (each holds its map, its cell and a worker). A create or a wake past it
    first puts the least recently used idle session to sleep (to its journal; the next request for it wakes
    it); when every live session is busy it is refused (503). 0: no limit."""
    max_session_voxels: int = 4_000_000
    """Voxels a session's map may grow to at most (``(voxel.max_extent / voxel.resolution)^3``), checked when a
    session is created (422 beyond it, with the numbers). What a live session costs the server grows with its grid:
    about 0.15 GB (mesh, cell, surface) plus 50 to 90 B a voxel (benchmarks/bench_session_memory.py: 1 mm over
    0.3 m, an 11 M-voxel grid, took 0.70 GB; 2 mm, 1.4 M voxels, 0.27 GB), so the default keeps the default
    ``max_live_sessions`` (16) within about 6 GB of a 24 GB machine (16 x (0.15 GB + 4 M x 60 B)), its workers
    beside them; the paper's default grid (1 m at 1 cm) is 1 M voxels. 0: no limit (the operator's own risk)."""
    max_class_seats: int = 40
    """Seats a class (class mode, docs/class.md) may have at most (422 beyond it). A class raises the live
    limit to hold its seats: ``max_live_sessions`` counts as at least the seats of all classes, up to this many."""
    idle_sleep: float = 1800.0
    """A live session nobody asked anything for this many seconds is put to sleep (its memory freed, its
    journal kept); the next request for it or a tab opening it resumes it transparently. 0: never."""
    mesh_load_memory: int = 3_000_000_000
    """Bytes of memory the child process that reads a mesh file may allocate (workbench/sources/mesh_loader.py); a file
    that needs more is refused (413) and the server's memory stays as it was."""
    mesh_load_timeout: float = 60.0
    """Seconds the child process that reads a mesh file may take; a slower file is refused (413). 0: no limit."""
    trash_max_bytes: int = 500 * 1024 * 1024
    """Deleted sessions wait in ``data_dir/sessions/.trash``; beyond this total size the oldest are removed."""
    trash_max_age: float = 7 * 24 * 3600.0
    """A deleted session older than this (seconds) is removed from the trash."""
    journal: bool = True
    """Journal every session under ``data_dir/sessions`` (resume after a crash, ``nbv replay``)."""
    faults: FaultConfig = field(default_factory=FaultConfig)
    """Faults injected into every new session's devices (a session's own ``faults`` replace these)."""
    planner: PlannerConfig = field(default_factory=PlannerConfig)
    """Default planner configuration; a session's ``config`` overrides any subset of it."""
    devices: DeviceConfig = field(default_factory=DeviceConfig)
    """The simulated devices. ``devices.model`` is the default model (a built-in name or a file
    in models_dir), ``devices.size`` / ``devices.up`` apply to every model file."""
    surface_score_points: int = SURFACE_SAMPLES
    """Points sampled on a simulated session's reconstructed surface to score it against the ground truth at each
    view (precision, recall, F, chamfer; workbench/surface/scoring.py). 100,000 puts them about 0.8 mm apart on
    the bunny, well below the 2 mm of the finest score, and costs about 0.15 s of CPU a view; fewer cost less, and
    on a large object spread the points so far apart that they score a good surface's recall at 2 mm low."""
    cell: str = ""
    """A cell file (docs/hardware.md): new sessions drive its camera, arm and turntable (source ``hardware``,
    workbench/sources/hardware.py). "" = simulated sessions. Read when a session is created or resumed."""
    dry_run: bool = False
    """With ``cell``: hardware sessions plan, preview and take approvals as usual, but their captures come
    from the simulator on the cell file's arm model and no device is opened or moved (rehearse a scan)."""

    def __post_init__(self) -> None:
        if not integer(self.max_upload_bytes) or self.max_upload_bytes < 1:
            raise ValueError(f"server.max_upload_bytes: must be a positive integer, got {self.max_upload_bytes!r}")
        for name in (
            "capture_timeout",
            "move_timeout",
            "plan_budget",
            "capture_budget",
            "trash_max_age",
            "mesh_load_timeout",
            "idle_sleep",
        ):
            value = getattr(self, name)
            if not finite(value):
                raise ValueError(f"server.{name}: must be a number of seconds (0: no limit), got {value!r}")
            if value < 0:
                raise ValueError(f"server.{name}: must be >= 0 (0: no limit), got {value!r}")
        if not isinstance(self.cell, str):
            raise ValueError(f'server.cell: must be the path of a cell file or "", got {self.cell!r}')
        if not isinstance(self.dry_run, bool):
            raise ValueError(f"server.dry_run: expected true/false, got {self.dry_run!r}")
        for name in (
            "max_running_jobs",
            "max_idle_workers",
            "trash_max_bytes",
            "mesh_load_memory",
            "max_live_sessions",
            "max_session_voxels",
            "max_class_seats",
        ):
            value = getattr(self, name)
            if not integer(value) or value < 0:
                raise ValueError(f"server.{name}: must be an integer >= 0, got {value!r}")
        points = self.surface_score_points
        if not integer(points) or not MIN_SCORE_POINTS <= points <= MAX_SCORE_POINTS:
            raise ValueError(
                f"server.surface_score_points: an integer in [{MIN_SCORE_POINTS}, {MAX_SCORE_POINTS}], got {points!r}"
            )
        if isinstance(self.mesh_limits, dict):
            try:
                object.__setattr__(self, "mesh_limits", MeshLimits(**self.mesh_limits))
            except TypeError as exc:
                raise ValueError(f"server.mesh_limits: {exc}") from None
        if not isinstance(self.mesh_limits, MeshLimits):
            raise ValueError("server.mesh_limits: must be a table of MeshLimits fields")
        if not isinstance(self.workers, bool):
            raise ValueError(f"server.workers: must be true or false, got {self.workers!r}")
        if not isinstance(self.faults, FaultConfig):
            raise ValueError("faults: must be a FaultConfig")
        object.__setattr__(self, "models_dir", Path(self.models_dir))
        object.__setattr__(self, "data_dir", Path(self.data_dir))

    def replace(self, **changes: Any) -> Any:
        """A copy with some fields changed (of the same class)."""
        return dataclasses.replace(self, **changes)
