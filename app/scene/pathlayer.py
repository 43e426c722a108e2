"""The ``path`` layer: the camera frustums along the move to the selected view, before it is approved.

A move is not a jump: the plate turns, the arm runs its trajectory, and a cell that captures during moves
(``move_capture_hz`` > 0) takes a frame at each of its capture times on the way. The layer draws the camera where
those frames would be taken (:func:`devices.move_capture.capture_times` of the move's duration at the cell's rate;
:data:`PREVIEW_HZ` when the cell does not capture during moves), small and translucent, and a line through the
camera's centre from where it stands to the selected view. The poses are those of the motion the cell plans for
the approval (:class:`app.scene.movetarget.SessionMoves`) as the cell executes it
(:class:`devices.move_capture.MovePath`), so the layer shows the way the camera really goes round the object:
the plate's turn sweeps it along a circle about the plate's axis, then the arm's trajectory.

Nodes: ``/path/frustums`` (one batched mesh: a filled pyramid per frame, translucent), ``/path/edges`` (their
outlines, one line-segment node) and ``/path/line`` (the centre's way, from the current pose to the view).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import numpy as np
from numpy.typing import NDArray

from app.scene.geometry import COLORS
from app.scene.movetarget import ArmTarget
from devices.cell import ScanCell
from devices.move_capture import capture_times
from planner import Pose

PREVIEW_HZ = 2.5
"""Frames per second drawn along a move when the cell does not capture during moves: the rate the offline estimate
found within 3 % of 5 Hz in coverage, so the frustums show the views a move could add without crowding."""
MAX_FRUSTUMS = 60
"""Frustums drawn per move at most (a 30 Hz camera on a 6 s move takes 180 frames): more are thinned evenly; the
REST read (``GET /api/sessions/{id}/plan/path``) lists every one."""
LINE_STEP = 0.05
"""Seconds between the points of the centre's line (at most :data:`LINE_POINTS`)."""
LINE_POINTS = 400
FRUSTUM_SCALE = 0.04
"""Metres from a path frustum's apex to its image plane (the views taken are drawn at 0.045, the next view at 0.07)."""
FRUSTUM_OPACITY = 0.35
PATH_COLORS: tuple[tuple[int, int, int], tuple[int, int, int]] = (COLORS["path"], (0, 90, 255))
"""RGB of the path's first and last frame (a light cyan to a deep blue: the way's direction); the line takes the
first."""


@dataclass(frozen=True, eq=False)
class PathPreview:
    """The camera along the move to the selected view.

    target: the move (its ``path`` set). rate_hz: the frames per second drawn. captured: True when the cell takes
    those frames (``move_capture_hz`` > 0), False for the preview rate. times: (K,) the frames' times since the move
    starts, strictly inside it; poses: K ``T_table_camera``. line_times: (L,) from 0 to the move's duration;
    line: L ``T_table_camera`` (the first where the camera stands, the last the selected view).
    """

    target: ArmTarget
    rate_hz: float
    captured: bool
    times: NDArray[np.float64]
    poses: tuple[Pose, ...]
    line_times: NDArray[np.float64]
    line: tuple[Pose, ...]

    @property
    def duration(self) -> float:
        return float(self.line_times[-1])

    def drawn(self) -> tuple[NDArray[np.float64], tuple[Pose, ...]]:
        """(times, poses) of the frustums drawn: every frame up to :data:`MAX_FRUSTUMS`, else as many evenly spread."""
        k = len(self.poses)
        if k <= MAX_FRUSTUMS:
            return self.times, self.poses
        pick = np.unique(np.round(np.linspace(0, k - 1, MAX_FRUSTUMS)).astype(int))
        return self.times[pick], tuple(self.poses[i] for i in pick)

    def to_json(self) -> dict[str, Any]:
        """The REST read's body (``PathOut``): the target, the rate, the frames, the start and the end."""
        return {
            "target": self.target.to_json(),
            "rate_hz": self.rate_hz,
            "captured": self.captured,
            "duration": self.duration,
            "frames": [{"t": float(t), **p.to_dict()} for t, p in zip(self.times, self.poses, strict=True)],
            "start": self.line[0].to_dict(),
            "end": self.line[-1].to_dict(),
        }


def no_path_json(target: ArmTarget) -> dict[str, Any]:
    """The REST read's body for a target without a path (unreachable, or a move that is not timed)."""
    return {"target": target.to_json(), "rate_hz": None, "captured": False, "duration": None, "frames": [],
            "start": None, "end": None}  # fmt: skip


def path_preview(target: ArmTarget | None, capture_hz: float) -> PathPreview | None:
    """The path layer's frames of ``target``'s move: at ``capture_hz`` when the cell captures during moves (> 0),
    else at :data:`PREVIEW_HZ`. None without a reachable, timed move."""
    if target is None or target.path is None:
        return None
    path = target.path
    rate = float(capture_hz) if capture_hz > 0 else PREVIEW_HZ
    duration = path.duration
    times = capture_times(duration, rate)
    steps = max(2, min(LINE_POINTS, math.ceil(duration / LINE_STEP) + 1))
    line_times = np.linspace(0.0, duration, steps)
    return PathPreview(
        target, rate, capture_hz > 0, times, tuple(path.poses(times)), line_times, tuple(path.poses(line_times))
    )


def frustum_pyramid(fov_y: float, aspect: float) -> tuple[NDArray[np.float32], NDArray[np.uint32]]:
    """(5, 3) vertices and (6, 3) faces of a camera's pyramid of unit depth (apex at the centre, OpenCV axes: the
    image plane at z = 1), closed by its image rectangle."""
    h = math.tan(fov_y / 2.0)
    w = h * aspect
    vertices = np.array([[0, 0, 0], [-w, -h, 1], [w, -h, 1], [w, h, 1], [-w, h, 1]], dtype=np.float32)
    faces = np.array([[0, 1, 2], [0, 2, 3], [0, 3, 4], [0, 4, 1], [1, 3, 2], [1, 4, 3]], dtype=np.uint32)
    return vertices, faces


PYRAMID_EDGES = ((0, 1), (0, 2), (0, 3), (0, 4), (1, 2), (2, 3), (3, 4), (4, 1))


def frustum_edges(poses: tuple[Pose, ...], fov_y: float, aspect: float, scale: float) -> NDArray[np.float32]:
    """(8 K, 2, 3) the outlines of K pyramids of depth ``scale`` at ``poses`` (table frame)."""
    vertices, _ = frustum_pyramid(fov_y, aspect)
    local = vertices.astype(np.float64) * scale
    out = []
    for pose in poses:
        world = local @ pose.rotation.T + pose.translation
        out.extend((world[a], world[b]) for a, b in PYRAMID_EDGES)
    return np.asarray(out, dtype=np.float32).reshape(-1, 2, 3)


def frame_colors(k: int) -> NDArray[np.uint8]:
    """(k, 3) the frames' colours, first to last along :data:`PATH_COLORS`."""
    a, b = (np.asarray(c, dtype=np.float64) for c in PATH_COLORS)
    s = np.linspace(0.0, 1.0, k)[:, None] if k > 1 else np.zeros((k, 1))
    return np.round(a * (1 - s) + b * s).astype(np.uint8)


def capture_rate(cell: ScanCell) -> float:
    """The frames per second ``cell`` takes during moves (``CellConfig.move_capture_hz``, the session's
    ``move_capture`` when it was created with one; 0: it does not)."""
    return float(cell.config.move_capture_hz)
