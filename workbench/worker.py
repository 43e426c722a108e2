"""What runs inside a session's worker process: the heavy, GIL-holding work of a session, on request.

The server (workbench/engine.py) sends ``(kind, payload)`` over a Pipe and receives ``("ok", result)`` or
``("error", exception)``. Every job carries the state it needs (the planner is pickled in and the planner
after the job pickled back), so a killed worker loses nothing: the server process keeps the session's planner
and a fresh worker takes up the next job. Jobs:

- ``("render", RenderSpec)`` once per process, then ``("render", T_table_camera)``: (H, W) float32 depth of the
  simulated camera (open3d ``cast_rays``, which holds the GIL for the whole image);
- ``("plan", (planner, cell_config))``: ``(PlanResult, planner)``, reachability by the cell's geometry;
- ``("integrate", (planner, frame))``: ``(IntegrationReport, planner)``.

This module imports the planner and (on the first render) open3d; the server imports it only to name the
target of its processes, and the forkserver preloads it so a new worker starts in milliseconds.
"""

from __future__ import annotations

from dataclasses import dataclass
from multiprocessing.connection import Connection
from typing import Any, cast

import numpy as np
from numpy.typing import NDArray

from devices.cell import Cell
from devices.config import CameraConfig, CellConfig
from planner import DepthFrame, Planner, Pose
from workbench.planning import plan_in


@dataclass(frozen=True, eq=False)
class RenderSpec:
    """What a worker needs to render a session's simulated camera.

    vertices: (V, 3) float64 object mesh in the table frame; faces: (F, 3) int64.
    """

    vertices: NDArray[np.float64]
    faces: NDArray[np.int64]
    camera: CameraConfig
    plate_radius: float
    plate_thickness: float


class _Worker:
    def __init__(self) -> None:
        self.camera: Any = None
        self.geometry: dict[CellConfig, Cell] = {}

    def setup(self, spec: RenderSpec) -> None:
        import trimesh

        from devices.sim import SimulatedCamera

        mesh = trimesh.Trimesh(spec.vertices, spec.faces, process=False)
        self.camera = SimulatedCamera(
            mesh, spec.camera, plate_radius=spec.plate_radius, plate_thickness=spec.plate_thickness
        )

    def render(self, pose: Pose) -> NDArray[np.float32]:
        if self.camera is None:
            raise RuntimeError("worker: render before setup")
        return self.camera.render(pose)

    def reach(self, config: CellConfig) -> Cell:
        """A cell of no devices: only its geometry (``is_reachable`` reads ``config`` alone; a session with an arm
        model plans in the server, see ``Session.make_plan``)."""
        if config not in self.geometry:
            self.geometry[config] = Cell(cast(Any, None), cast(Any, None), cast(Any, None), config)
        return self.geometry[config]

    def run(self, kind: str, payload: Any) -> Any:
        if kind == "setup":
            return self.setup(payload)
        if kind == "render":
            return self.render(payload)
        if kind == "plan":
            planner, config = cast(tuple[Planner, CellConfig], payload)
            plan = plan_in(self.reach(config), planner)
            return plan, planner
        if kind == "integrate":
            planner, frame = cast(tuple[Planner, DepthFrame], payload)
            report = planner.integrate(frame)
            return report, planner
        if kind == "sleep":  # tests: a job that holds the worker (like a plan that never ends)
            import time

            time.sleep(float(payload))
            return None
        raise ValueError(f"worker: unknown job {kind!r}")


def serve(conn: Connection) -> None:
    """The worker process's main loop: one job at a time until the pipe closes."""
    worker = _Worker()
    while True:
        try:
            kind, payload = conn.recv()
        except (EOFError, OSError):
            return
        try:
            answer: tuple[str, Any] = ("ok", worker.run(kind, payload))
        except Exception as exc:
            answer = ("error", exc)
        try:
            conn.send(answer)
        except Exception as exc:  # an exception (or a result) that does not pickle
            conn.send(("error", RuntimeError(f"worker: cannot send the answer of {kind}: {exc!r}")))
