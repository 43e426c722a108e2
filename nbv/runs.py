"""One run of ``nbv bench``: what a worker needs (:class:`RunTask`) and what it returns (:class:`RunOutcome`)."""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

from planner.config import PlannerConfig


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
    reachable: bool = False
    """Compute the reachable-coverage ceiling of (model, seed) in this run."""
    threads: int | None = None
    """BLAS/OpenMP threads of the worker (None: library default)."""
    arm: str = "urdf"
    """The cell's arm (``--arm``): 'urdf' (the UR5) or 'reach_sphere'."""


@dataclass
class RunOutcome:
    """A finished (or failed) run: CSV rows without ``reachable_coverage``, and what runs.json records."""

    label: str
    planner: str
    seed: int
    rows: list[dict[str, Any]] = field(default_factory=list)
    poses: list[dict[str, list[float]]] = field(default_factory=list)
    terminated: str | None = None
    seconds: float = 0.0
    reachable_coverage: float | None = None
    reachable_error: str | None = None
    error: str | None = None

    @staticmethod
    def failed(task: RunTask, error: str) -> RunOutcome:
        return RunOutcome(task.label, task.planner, task.seed, error=error)

    def to_json(self) -> dict[str, Any]:
        return {
            "model": self.label,
            "planner": self.planner,
            "seed": self.seed,
            "views": len(self.rows),
            "final_coverage": self.rows[-1]["coverage"] if self.rows else None,
            "terminated": self.terminated,
            "seconds": self.seconds,
            "reachable_coverage": self.reachable_coverage,
            "reachable_error": self.reachable_error,
            "error": self.error,
            "poses": self.poses,
        }
