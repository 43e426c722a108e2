"""``LiveSurface``: a session's surface as it follows the scan, and :class:`SurfaceUpdate`, what the server keeps.

It runs where the session's integration runs (its worker process, workbench/workers/child.py): each captured
view's registered frame is fused (:class:`SurfaceIntegrator`), the surface extracted and reduced to the
layer's triangle budget (:func:`layer_mesh`, vertex clustering: fast). The pose fused is the one the journal keeps (``pose_used``, through its JSON form), so
a rebuild from the journal (workbench/journal/surface.py) fuses the same numbers and gives the same surface.
A surface that cannot be built never fails a capture: the update says why (``error``).
"""

from __future__ import annotations

import logging
import time
from dataclasses import dataclass
from typing import Any

from planner import DepthFrame, Pose
from workbench.evaluation.accuracy import Accuracy, GroundTruth
from workbench.surface.config import SurfaceConfig
from workbench.surface.export import LAYER_TRIANGLES, layer_bytes, layer_mesh
from workbench.surface.integrator import SurfaceIntegrator
from workbench.surface.mesh import SurfaceMesh
from workbench.surface.report import SCORES
from workbench.surface.scoring import surface_accuracy

log = logging.getLogger(__name__)


@dataclass(frozen=True, eq=False)
class SurfaceUpdate:
    """A session's surface after ``views`` views: the full mesh (export), its simplified layer (the page), or why
    there is none (``error``: no view saw the object yet, or the reconstruction failed)."""

    views: int
    mesh: SurfaceMesh | None
    layer: SurfaceMesh | None
    error: str | None
    seconds: float
    """Wall time of the last update (integrate, extract, simplify), in the process that ran it."""
    accuracy: Accuracy | None = None
    """The surface against the ground truth (simulated sessions), the shared metric; None without either."""
    cpu_seconds: float = 0.0
    """CPU time of the same update (every thread of the process): what the machine's load does not inflate."""

    @property
    def fscore_5mm(self) -> float | None:
        """The surface's F-score at 5 mm, None without a surface or a ground truth."""
        return None if self.accuracy is None else self.accuracy.fscore_5mm

    @property
    def layer_bytes(self) -> int:
        """Bytes the page's layer sends (0 without a surface)."""
        return 0 if self.layer is None else layer_bytes(self.layer)


def journaled_pose(pose: Pose) -> Pose:
    """``pose`` as the journal gives it back (``Pose.from_dict`` of its dict): live and rebuilt fuse the same."""
    return Pose.from_dict(pose.to_dict())


class LiveSurface:
    """One session's incremental surface: :meth:`add` a registered frame per view, read :attr:`update`."""

    def __init__(
        self,
        config: SurfaceConfig | None = None,
        max_triangles: int = LAYER_TRIANGLES,
        truth: GroundTruth | None = None,
    ) -> None:
        self.integrator = SurfaceIntegrator(config)
        self.max_triangles = max_triangles
        self.truth = truth
        """The ground truth each extracted surface is scored against (None: not scored)."""
        self.views = 0
        """Views offered (a frame the surface could not use counts: it follows the session's views)."""
        self.update = SurfaceUpdate(0, None, None, "no view captured yet", 0.0)

    def fuse_move_frame(self, frame: DepthFrame, T_world_camera: Pose) -> None:
        """Fuse a frame taken during a move (capture during moves) at its registered pose: no view of its own, no
        extraction (the view the move led to extracts). Never raises: a failure is logged."""
        try:
            self.integrator.integrate(frame.with_pose(journaled_pose(T_world_camera)))
        except Exception as exc:  # a surface never fails a capture
            log.warning(
                "surface: a move frame before view %d not fused: %s: %s", self.views + 1, type(exc).__name__, exc
            )

    def add(self, frame: DepthFrame, T_world_camera: Pose, extract: bool = True) -> SurfaceUpdate:
        """Fuse ``frame`` at its registered pose ``T_world_camera``; with ``extract`` the surface and its layer
        are extracted (a rebuild extracts once, after its last frame). Never raises: a failure is the update's
        ``error`` (and a logged warning)."""
        t0, c0 = time.perf_counter(), time.process_time()
        self.views += 1
        error: str | None = None
        try:
            self.integrator.integrate(frame.with_pose(journaled_pose(T_world_camera)))
        except Exception as exc:  # a surface never fails a capture
            error = f"view {self.views} not fused: {type(exc).__name__}: {exc}"
            log.warning("surface: %s", error)
        if extract:
            self.extract(time.perf_counter() - t0, error, time.process_time() - c0)
        return self.update

    def extract(self, seconds: float = 0.0, error: str | None = None, cpu_seconds: float = 0.0) -> SurfaceUpdate:
        """Extract the surface and its layer now, scored when there is a ground truth (the update; ``error``
        noted when nothing else went wrong). ``seconds``, ``cpu_seconds`` (the update's wall and CPU time so far,
        the fusion's) grow by the extraction's; they leave the scoring out."""
        t0, c0 = time.perf_counter(), time.process_time()
        mesh = layer = None
        try:
            mesh = self.integrator.mesh()
            layer = layer_mesh(mesh, self.max_triangles)
        except Exception as exc:
            mesh, layer = None, None
            error = f"{type(exc).__name__}: {exc}" if error is None else error
        seconds += time.perf_counter() - t0
        cpu_seconds += time.process_time() - c0
        accuracy = None
        if mesh is not None and self.truth is not None:
            try:
                accuracy = surface_accuracy(mesh, self.truth)
            except Exception as exc:
                log.warning("surface: not scored: %s", exc)
        self.update = SurfaceUpdate(self.views, mesh, layer, error, seconds, accuracy, cpu_seconds)
        return self.update


def update_block(update: SurfaceUpdate | None) -> dict[str, Any]:
    """The ``surface`` block of a session's export: the scores of :data:`report.SCORES` (None without a ground
    truth), ``triangles``, ``layer_triangles``, ``views``, ``seconds`` (the last update) and ``error`` (why there
    is no surface, else None)."""
    if update is None:
        update = SurfaceUpdate(0, None, None, "no view captured yet", 0.0)
    block: dict[str, Any] = dict.fromkeys(SCORES)
    if update.accuracy is not None:
        block |= {key: getattr(update.accuracy, key) for key in SCORES}
    return block | {
        "triangles": 0 if update.mesh is None else update.mesh.triangles,
        "layer_triangles": 0 if update.layer is None else update.layer.triangles,
        "views": update.views,
        "seconds": update.seconds,
        "error": update.error,
    }
