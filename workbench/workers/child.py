"""What runs inside a session's worker process: the heavy, GIL-holding work of a session, on request.

The server (workbench/workers/client.py) sends ``(kind, payload)`` over a Pipe and receives ``("ok", result)`` or
``("error", exception)``. Every job carries the state it needs (the planner is pickled in and the planner
after the job pickled back), so a killed worker loses nothing: the server process keeps the session's planner
and a fresh worker takes up the next job. Jobs:

- ``("truth", TruthSpec)`` once per process (simulated sessions): what the surface is scored against;
- ``("render", RenderSpec)`` once per process, then ``("render", T_table_camera)``: (H, W) float32 depth of the
  simulated camera (open3d ``cast_rays``, which holds the GIL for the whole image);
- ``("plan", (planner, cell_config, q, angle))``: ``("progress", PlanProgress)`` messages on the way, then
  ``(PlanResult, planner)``, reachability by the cell's geometry
  and, for an arm model, its kinematics with the arm at joints ``q`` and the plate at ``angle`` (the same
  verdicts as the server's cell: reachability is a pure function of the view and the object box);
- ``("integrate", (planner, frame, journal_dir, moving))``: ``(IntegrationReport, planner, SurfaceUpdate, moves)``: the frame
  at its registered pose fused into the session's surface, which this process keeps between jobs (a new
  process rebuilds it from the journal in ``journal_dir`` first, workbench/journal/surface.py);
- ``("rebuild", (journal, cell_config, q, angle, surface_samples))``: ``("progress", (stage, done, total))``
  messages on the way, then the ``Rebuilt`` session (a resume or a discard replays its journal here), its
  surface rebuilt too (``Rebuilt.surface``);
- ``("timeline", (journal, cell_config, q, angle, surface_samples))``: ``("progress", (stage, done, total))``
  messages on the way, then the ``TimelineStep`` of every kept view (workbench/journal/timeline.py); the worker's
  own surface stays as it was (a timeline reads the journal only, it changes nothing of the session);
- ``("warm", (cell_config, q, angle, planner_config))`` once per process, right after it starts (while the person
  captures): the planning cell's arm model built, the planner's modules imported and the reachability of the
  first plan's candidates cached, so the session's first plan does not pay for them (:meth:`_Worker.warm`); cut
  short when a job is already waiting for it (the server sets the process's ``hurry`` event) or when the machine's
  cores stay busy (workbench/workers/spare.py);
- ``("fit", (points_world, cluster_config, resolution, kind, t))``: ``(ellipsoids, ClusterFit)`` of one voxel
  kind at exactly T components (``planner.ellipsoids.fit_at_t``: the Fit panel's "fit at another T").

This module imports the planner and (on the first render) open3d; the server imports it only to name the
target of its processes, and the forkserver preloads it so a new worker starts in milliseconds.
"""

from __future__ import annotations

import contextlib
import time
from collections.abc import Callable
from dataclasses import dataclass
from multiprocessing.connection import Connection
from typing import Any, cast

import numpy as np
from numpy.typing import NDArray

from devices.cell import Cell
from devices.config import CameraConfig, CellConfig
from planner import DepthFrame, Planner, Pose
from planner.progress import PlanProgress
from workbench.evaluation.accuracy import GroundTruth
from workbench.journal.rebuild import Rebuilt
from workbench.journal.store import Journal
from workbench.journal.surface import in_step, surface_of_journal
from workbench.journal.timeline import TimelineStep
from workbench.planning import plan_in
from workbench.progress import Throttle
from workbench.surface.live import LiveSurface
from workbench.workers.spare import SHARE, SpareCore

WARM_BOX = ((-0.1, -0.1, 0.0), (0.1, 0.1, 0.2))
"""The nominal object box (table frame, m) whose hemisphere a new worker's IK is warmed on: an object of the default
0.2 m size on the plate."""


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


@dataclass(frozen=True, eq=False)
class TruthSpec:
    """The ground truth a worker scores the session's surface against (simulated sessions).

    vertices: (V, 3) float64 and faces: (F, 3) int64 of the object in the table frame; samples: (M, 3) float64
    points uniform on it (the session's ``surface_samples``); surface_points: how many points the surface is
    sampled with to score it (the server's ``surface_score_points``; None: the scorer's default).
    """

    vertices: NDArray[np.float64]
    faces: NDArray[np.int64]
    samples: NDArray[np.float64]
    surface_points: int | None = None


class _ArmState:
    """The arm as a planning cell reads it (``joint_positions()``): the session's joints, sent with each job
    (move costs start there; a rebuild resets them to each capture's). It moves nothing."""

    def __init__(self, joint_names: tuple[str, ...], q: NDArray[np.float64]) -> None:
        self.joint_names = joint_names
        self.q = q

    def joint_positions(self) -> NDArray[np.float64]:
        return self.q

    def reset(self, q: NDArray[np.float64]) -> None:
        self.q = np.asarray(q, dtype=np.float64)

    def execute(self, trajectory: object) -> None:
        raise RuntimeError("worker: a planning cell does not move")

    def stop(self) -> None:
        pass


class _PlateState:
    """The turntable as a planning cell reads it (``angle``). It turns nothing."""

    def __init__(self) -> None:
        self.angle = 0.0

    def reset(self, angle: float) -> None:
        self.angle = float(angle)

    def rotate_to(self, angle: float) -> None:
        raise RuntimeError("worker: a planning cell does not move")


class _Throttled:
    """A plan's progress, sent on when :class:`workbench.progress.Throttle` says it is worth it."""

    def __init__(self, send: Callable[[Any], None]) -> None:
        self.send = send
        self.throttle = Throttle()

    def __call__(self, progress: PlanProgress) -> None:
        if self.throttle(progress.stage, progress.done, progress.total):
            self.send(progress)


def _sleep(seconds: float) -> bool:
    """A pause with nobody to wake it (a worker outside a process, as in tests): False, no job arrived."""
    time.sleep(seconds)
    return False


class _Worker:
    def __init__(self) -> None:
        self.camera: Any = None
        self.geometry: dict[CellConfig, tuple[Cell, tuple[_ArmState, _PlateState] | None]] = {}
        self.surface: LiveSurface | None = None
        """The session's surface, kept between jobs (None in a new process)."""
        self.truth: GroundTruth | None = None
        """What the surface is scored against (the ``truth`` job, once per process), None: not scored."""
        self.hurry: Callable[[], bool] = lambda: False
        """True once a job waits for this process: the warm-up stops where it is (:meth:`warm`)."""
        self.wait_for_job: Callable[[float], bool] = _sleep
        """Sleep up to the seconds given; True when a job arrived meanwhile (the warm-up's pauses)."""
        self.warm_share = SHARE
        """The share of a core the warm-up must get to go on (:class:`SpareCore`; 0: always)."""

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

    def reach(self, config: CellConfig, q: NDArray[np.float64] | None, angle: float) -> Cell:
        """A cell of no devices: ``config``'s geometry and, for an arm model (``q`` given), its kinematics (built
        once per worker) with the arm at joints ``q`` (n,) and the plate at ``angle`` (rad)."""
        if config not in self.geometry:
            if q is None:
                self.geometry[config] = (Cell(cast(Any, None), cast(Any, None), cast(Any, None), config), None)
            else:
                from devices.arm.kinematics import ArmKinematics

                kinematics = ArmKinematics(config.arm, config.plate_radius, config.plate_thickness)
                arm, plate = _ArmState(kinematics.joint_names, np.asarray(q, dtype=np.float64)), _PlateState()
                cell = Cell(cast(Any, None), arm, cast(Any, plate), config, kinematics=kinematics)
                self.geometry[config] = (cell, (arm, plate))
        cell, state = self.geometry[config]
        if state is not None and q is not None:
            state[0].reset(q)
            state[1].reset(angle)
        return cell

    def warm(self, config: CellConfig, q: NDArray[np.float64] | None, angle: float, planner_config: Any = None) -> None:
        """Build the planning cell of ``config`` (the arm model: URDF, collision world, IK seed library), import what
        a plan runs, and fill the reachability cache of the first plan's candidates with the arm at ``q``: in a
        simulated session (a render scene is set up) the candidates about the box the first frame at the cell's
        initial view gives ``planner_config``'s map (the frame rendered here, noise-free); otherwise about a
        nominal box (``WARM_BOX``). Reachability is a pure function of the view and the object box, so the plans
        are the same as without it; only the first one is faster. When :attr:`hurry` says a job waits (a capture
        right after the create), the reachability pass stops there: the plan asks the rest itself, and the job is
        not kept waiting for views the plan may never ask about. It is speculative, so it goes on only while it has
        a core to itself (:class:`workbench.workers.spare.SpareCore`: it pauses, then gives up, while the machine's
        other work wants the cores)."""
        import planner.baselines
        import planner.bic_search
        import planner.tour  # noqa: F401
        from planner import PlannerConfig
        from planner.candidates import propose_candidates
        from planner.types import BoundingBox

        cell = self.reach(config, q, angle)
        if cell.kinematics is None:
            return
        cfg = planner_config if isinstance(planner_config, PlannerConfig) else PlannerConfig()
        box = aim = BoundingBox(np.array(WARM_BOX[0]), np.array(WARM_BOX[1]))
        spare = SpareCore(self.hurry, self.wait_for_job, self.warm_share)
        if not spare.go():
            return
        if self.camera is not None:
            pose = cell.initial_pose()
            scratch = Planner(cfg)
            with contextlib.suppress(ValueError):  # nothing on the object from there: the nominal box
                scratch.integrate(DepthFrame(self.camera.render(pose), pose, self.camera.intrinsics))
            if scratch.voxel_map.bbox is not None:
                box, aim = scratch.voxel_map.bbox, scratch.candidate_box()
        candidates, _, _ = propose_candidates(aim, cfg.candidates, cfg.partitions)
        cell.set_object_box(box)
        try:
            for c in candidates:
                if not spare.go():
                    break
                cell.is_reachable(c.T_world_camera)
        finally:
            cell.set_object_box(None)

    def rebuild(self, payload: Any, send: Callable[[Any], None] | None) -> Rebuilt:
        """:func:`workbench.journal.rebuild.rebuild` of a journal in this worker's planning cell; the replayed
        captures' plans stay here (the pending and last plans travel in the result)."""
        from workbench.journal.rebuild import rebuild

        journal, cell, truth, report = self._replay_args(payload, send)
        rebuilt = rebuild(journal, cell, truth, report)
        for capture in rebuilt.captures:
            capture.plans.clear()
        self.surface = surface_of_journal(journal, self.truth)
        rebuilt.surface = self.surface.update
        return rebuilt

    def timeline(self, payload: Any, send: Callable[[Any], None] | None) -> list[TimelineStep]:
        """:func:`workbench.journal.timeline.timeline_of` a journal in this worker's planning cell."""
        from workbench.journal.timeline import timeline_of

        return timeline_of(*self._replay_args(payload, send))

    def _replay_args(self, payload: Any, send: Callable[[Any], None] | None) -> tuple[Journal, Cell, Any, Any]:
        """(journal, planning cell, coverage of a cloud or None, progress report) of a rebuild's payload
        ``(journal, cell_config, q, angle, surface_samples)``."""
        from workbench.evaluation.coverage import coverage

        journal, config, q, angle, samples = cast(tuple[Journal, CellConfig, Any, float, Any], payload)
        throttle = Throttle()

        def report(stage: str, done: int, total: int) -> None:
            if send is not None and throttle(stage, done, total):
                send((stage, done, total))

        truth = None if samples is None else (lambda cloud: coverage(samples, cloud))
        return journal, self.reach(config, q, angle), truth, report

    def run(self, kind: str, payload: Any, send: Callable[[Any], None] | None = None) -> Any:
        """The answer of one job; ``send`` ships ``("progress", value)`` messages to the server on the way."""
        if kind == "setup":
            return self.setup(payload)
        if kind == "truth":
            spec = cast(TruthSpec, payload)
            self.truth = GroundTruth(spec.vertices, spec.faces, spec.samples, spec.surface_points)
            return None
        if kind == "render":
            return self.render(payload)
        if kind == "warm":
            return self.warm(*cast(tuple[CellConfig, Any, float, Any], payload))
        if kind == "plan":
            planner, config, q, angle = cast(tuple[Planner, CellConfig, Any, float], payload)
            report = _Throttled(send) if send is not None else None
            plan = plan_in(self.reach(config, q, angle), planner, report)  # as in the server: the box, move costs
            return plan, planner
        if kind == "rebuild":
            return self.rebuild(payload, send)
        if kind == "timeline":
            return self.timeline(payload, send)
        if kind == "integrate":
            from workbench.move_frames import integrate_step

            planner, frame, journal_dir, moving = cast(tuple[Planner, DepthFrame, Any, Any], payload)
            views = len(planner.views)
            report, after, moves = integrate_step(planner, frame, moving)  # a rejected frame raises: no surface
            self.surface = in_step(self.surface, views, journal_dir, self.truth)
            for kept in [] if moves is None else moves.kept:
                self.surface.fuse_move_frame(kept.frame, kept.T_world_camera)
            return report, after, self.surface.add(frame, report.T_world_camera), moves
        if kind == "fit":
            from planner.ellipsoids import fit_at_t

            return fit_at_t(*payload)
        if kind == "sleep":  # tests: a job that holds the worker (like a plan that never ends)
            time.sleep(float(payload))
            return None
        raise ValueError(f"worker: unknown job {kind!r}")


def serve(conn: Connection, hurry: Any = None) -> None:
    """The worker process's main loop: one job at a time until the pipe closes. ``hurry``: a multiprocessing
    Event the server sets when a job waits (the warm-up then stops early), None: never."""
    worker = _Worker()
    if hurry is not None:
        worker.hurry = hurry.is_set
        worker.wait_for_job = hurry.wait
    while True:
        try:
            kind, payload = conn.recv()
        except (EOFError, OSError):
            return
        try:
            answer: tuple[str, Any] = ("ok", worker.run(kind, payload, lambda value: conn.send(("progress", value))))
        except Exception as exc:
            answer = ("error", exc)
        try:
            conn.send(answer)
        except Exception as exc:  # an exception (or a result) that does not pickle
            conn.send(("error", RuntimeError(f"worker: cannot send the answer of {kind}: {exc!r}")))
