"""One run of ``nbv bench``: what a worker needs (:class:`RunTask`, :class:`MeshPayload`) and what it
returns (:class:`RunOutcome`)."""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

import numpy as np
from numpy.typing import NDArray

from planner.config import PlannerConfig


@dataclass(frozen=True, eq=False)
class MeshPayload:
    """A placed mesh (table frame, before any ``--yaw`` turn) as plain arrays: what travels to a worker
    on another machine instead of a path on the client's file system.

    vertices: (V, 3) float64. faces: (F, 3) int64 indices into vertices.
    """

    vertices: NDArray[np.float64]
    faces: NDArray[np.int64]

    def __post_init__(self) -> None:
        v = np.ascontiguousarray(self.vertices, dtype=np.float64)
        f = np.ascontiguousarray(self.faces, dtype=np.int64)
        if v.ndim != 2 or v.shape[1] != 3 or not np.all(np.isfinite(v)):
            raise ValueError(f"vertices: expected finite (V, 3) values, got shape {v.shape}")
        if f.ndim != 2 or f.shape[1] != 3 or len(f) == 0 or f.min() < 0 or f.max() >= len(v):
            raise ValueError(f"faces: expected (F, 3) indices into {len(v)} vertices, got shape {f.shape}")
        object.__setattr__(self, "vertices", v)
        object.__setattr__(self, "faces", f)

    @staticmethod
    def of(mesh: Any) -> MeshPayload:
        """The payload of a trimesh mesh."""
        return MeshPayload(np.asarray(mesh.vertices), np.asarray(mesh.faces))

    def to_trimesh(self) -> Any:
        import trimesh

        return trimesh.Trimesh(self.vertices.copy(), self.faces.copy(), process=False)

    @property
    def nbytes(self) -> int:
        return int(self.vertices.nbytes + self.faces.nbytes)


@dataclass(frozen=True)
class RunTask:
    """One simulated scan of the bench: what a worker process needs (picklable)."""

    model: str
    """The ``--models`` entry: a built-in name or a mesh path."""
    label: str
    """The model's name in the outputs (unique within a bench)."""
    planner: str
    seed: int
    config: PlannerConfig
    size: float = 0.2
    up: str = "y"
    yaw_deg: float = 0.0
    """The object's turn about the turntable axis, degrees (``--yaw``)."""
    depth_noise: float = 0.0
    pose_noise: float = 0.0
    threads: int | None = None
    """BLAS/OpenMP threads of the worker (None: library default)."""
    arm: str | None = "urdf"
    """The cell's arm (``--arm``): a preset name or URDF file, 'urdf' (the arm of ``cell``, the UR5 by default),
    'reach_sphere', or None (``cell`` as it is)."""
    cell: Any = None
    """The cell's settings (``devices.config.CellConfig``, the ``--config`` file's ``[devices.cell]``); None: the
    default cell."""
    arm_label: str = ""
    """The arm's name in the outputs when a bench sweeps arms (``--arms``): the run's planner reads
    ``planner@arm`` and its rows carry it in the ``arm`` column ('' = no sweep)."""
    turn_while_moving: bool = False
    """The UR5 cell turns the plate while the arm moves when it may (``--turn-while-moving``,
    ``ArmConfig.turn_while_moving``)."""
    sensor: str = "ideal"
    """The depth sensor's model (``--sensor``)."""
    calibration: str = "none"
    """The cell's calibration error (``--calibration``)."""

    @property
    def run_planner(self) -> str:
        """The planner's name in the outputs: ``planner@arm`` in an arm sweep."""
        return f"{self.planner}@{self.arm_label}" if self.arm_label else self.planner


@dataclass
class RunOutcome:
    """A finished (or failed) run: its CSV rows (the ceiling columns are added by the report), and what
    runs.json records."""

    label: str
    planner: str
    seed: int
    yaw: float = 0.0
    """The placement: the object's turn about the turntable axis, degrees."""
    rows: list[dict[str, Any]] = field(default_factory=list)
    poses: list[dict[str, list[float]]] = field(default_factory=list)
    terminated: str | None = None
    seconds: float = 0.0
    error: str | None = None
    arm: str = ""
    """The arm's name when the bench sweeps arms ('' otherwise): its ceiling is the arm's own."""
    refused_moves: list[dict[str, Any]] = field(default_factory=list)
    icp_rejected: list[dict[str, Any]] = field(default_factory=list)

    @property
    def key(self) -> tuple[str, int, float]:
        """(model, seed, yaw): what pairs runs of different planners."""
        return (self.label, self.seed, self.yaw)

    @property
    def ceiling_key(self) -> tuple[str, float]:
        """The key of this run's reachable-coverage ceiling: (model, yaw), or (model@arm, yaw) in an arm sweep."""
        return (f"{self.label}@{self.arm}" if self.arm else self.label, self.yaw)

    @staticmethod
    def failed(task: RunTask, error: str) -> RunOutcome:
        return RunOutcome(task.label, task.run_planner, task.seed, task.yaw_deg, error=error, arm=task.arm_label)

    def to_json(self) -> dict[str, Any]:
        return {
            "model": self.label,
            "planner": self.planner,
            "arm": self.arm or None,
            "seed": self.seed,
            "yaw": self.yaw,
            "views": len(self.rows),
            "final_coverage": self.rows[-1]["coverage"] if self.rows else None,
            "terminated": self.terminated,
            "seconds": self.seconds,
            "error": self.error,
            "refused_moves": self.refused_moves,
            "icp_rejected": self.icp_rejected,
            "poses": self.poses,
        }
