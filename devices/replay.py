"""Replay devices: a camera that plays back recorded depth frames, and a cell around it.

This is how captures from another rig enter the workbench, and how a journaled
session is re-run. The frames come from

- a *recording folder* (:func:`load_recording`): one ``NAME.ply`` + ``NAME.json``
  pair per view, in name order, plus an optional ``intrinsics.json``; the format
  is documented in ``docs/journal.md``; or
- any sequence of :class:`planner.types.DepthFrame` (the journal's ``.npz`` frames).

Two modes: ``"sequence"`` returns frame 1, 2, 3, ... whatever pose was asked for
(the recorded pose is kept, so the planner integrates the view that was really
taken); ``"nearest"`` returns the recorded frame whose camera is nearest to the
pose the cell was moved to (a dense recording then acts as a cell that can only
stop at the recorded views).
"""

from __future__ import annotations

import json
import math
from collections.abc import Sequence
from pathlib import Path
from typing import TYPE_CHECKING, Any, Literal

import numpy as np

from devices.cell import Cell, Motion, rz
from devices.cellreach import SphereReach
from devices.config import CellConfig
from devices.move_capture import OnFrame
from devices.ply import read_ply
from devices.protocols import CaptureError
from devices.sim import SimulatedArm, SimulatedTurntable
from planner.types import BoundingBox, DepthFrame, Intrinsics, Pose

if TYPE_CHECKING:
    from devices.arm.kinematics import ArmKinematics

ReplayMode = Literal["sequence", "nearest"]
MAX_VIEWS = 200
"""A recording folder may hold at most this many views."""


class ReplayCamera:
    """A camera playing back ``frames`` (all with the same intrinsics).

    mode: "sequence" (in order; CaptureError when all were played) or "nearest"
    (the frame whose camera position is nearest ``pose_source()``).
    """

    def __init__(
        self, frames: Sequence[DepthFrame], mode: ReplayMode = "sequence", pose_source: Any | None = None
    ) -> None:
        if len(frames) == 0:
            raise ValueError("replay: no frames to play back")
        if mode not in ("sequence", "nearest"):
            raise ValueError(f"replay mode: 'sequence' or 'nearest', got {mode!r}")
        k = frames[0].intrinsics
        for i, frame in enumerate(frames):
            if not isinstance(frame, DepthFrame):
                raise ValueError(f"replay frame {i}: expected a DepthFrame, got {type(frame).__name__}")
            if frame.intrinsics != k:
                raise ValueError(f"replay frame {i}: intrinsics differ from frame 0's")
        self.frames = tuple(frames)
        self.mode: ReplayMode = mode
        self.pose_source = pose_source
        self.position = 0
        self.captures = 0
        self.fail_next: Exception | None = None
        self._positions = np.array([f.T_world_camera.translation for f in self.frames])

    @property
    def intrinsics(self) -> Intrinsics:
        return self.frames[0].intrinsics

    def capture(self) -> DepthFrame:
        if self.fail_next is not None:
            exc, self.fail_next = self.fail_next, None
            raise exc
        if self.mode == "sequence":
            if self.position >= len(self.frames):
                raise CaptureError(f"replay: all {len(self.frames)} recorded frames have been played back")
            frame = self.frames[self.position]
            self.position += 1
        else:
            if self.pose_source is None:
                raise CaptureError("replay camera: no pose source (it is not mounted in a cell)")
            where = self.pose_source().translation
            frame = self.frames[int(np.argmin(np.linalg.norm(self._positions - where, axis=1)))]
        self.captures += 1
        return frame

    def device_state(self) -> dict[str, Any]:
        return {"position": self.position}

    def restore_device_state(self, state: dict[str, Any]) -> None:
        position = int(state["position"])
        if not 0 <= position <= len(self.frames):
            raise ValueError(f"replay position {position} outside [0, {len(self.frames)}]")
        self.position = position


class ReplayReach(SphereReach):
    """A replay's reach: the moves of the reach sphere (the views were taken already), the reachability for planning
    that of ``config``: the URDF arm's IK and collision checks at the arm's home configuration (state-independent,
    so a replay sees the session's answers), or the reach sphere."""

    def __init__(self, config: CellConfig, arm: SimulatedArm, turntable: SimulatedTurntable) -> None:
        super().__init__(config, arm, turntable)
        self.model: ArmKinematics | None = None
        if config.kinematics == "urdf":
            from devices.arm.kinematics import ArmKinematics

            self.model = ArmKinematics(config.arm, config.plate_radius, config.plate_thickness)

    def reachability(self, T_table_camera: Pose) -> tuple[bool, str | None]:
        if self.model is not None:
            return self.model.reachability(T_table_camera, self.model.home, self._angle())
        return super().reachability(T_table_camera)

    def is_reachable(self, T_table_camera: Pose) -> bool:
        if self.model is not None:
            return self.reachability(T_table_camera)[0]
        return super().is_reachable(T_table_camera)

    def set_object_box(self, bbox: BoundingBox | None) -> None:
        if self.model is not None:
            self.model.set_object_box(*((bbox.lower, bbox.upper) if bbox is not None else (None, None)))


class ReplayCell(Cell):
    """A cell whose camera plays back recorded frames.

    The arm and turntable are simulated and never refuse a move (the views were already taken); reachability for
    planning is that of ``config`` (:class:`ReplayReach`). ``capture`` keeps each frame's recorded pose. The
    first view is the first recorded frame's pose.
    """

    def __init__(self, frames: Sequence[DepthFrame], config: CellConfig | None = None, mode: ReplayMode = "sequence"):
        arm = SimulatedArm()
        turntable = SimulatedTurntable()
        camera = ReplayCamera(frames, mode, pose_source=lambda: self.pose)
        config = config if config is not None else CellConfig()
        super().__init__(camera, arm, turntable, config, reach=ReplayReach(config, arm, turntable))
        self.frames = camera.frames

    @property
    def reach_of_config(self) -> bool:
        """A replay judges reachability at the arm's home, not from the arm's state: a worker's planning cell
        would answer differently."""
        return False

    def initial_pose(self) -> Pose:
        return self.frames[0].T_world_camera

    def move_to(
        self,
        T_table_camera: Pose,
        plate_angle: float | None = None,
        then: Sequence[Pose] = (),
        motion: Motion | None = None,
        capture_hz: float = 0.0,
        on_frame: OnFrame | None = None,
    ) -> Motion:
        """Put the (virtual) camera at ``T_table_camera`` without turning the plate; no reach check. ``plate_angle``,
        ``then``, ``motion``, ``capture_hz`` and ``on_frame`` (:meth:`Cell.move_to`'s) are accepted and ignored: the views
        were taken already. The
        motion is not timed (``Motion.timed`` False)."""
        done = Motion(self.turntable.angle, rz(self.turntable.angle) @ T_table_camera, timed=False)
        self.arm.move_to(done.T_base_camera)
        return done

    def capture(self) -> DepthFrame:
        return self.camera.capture()


# ---------------------------------------------------------------------- recording folders


def _read_json(path: Path) -> Any:
    try:
        return json.loads(path.read_text(encoding="utf-8"))
    except (OSError, UnicodeDecodeError, json.JSONDecodeError) as exc:
        raise ValueError(f"{path.name}: not readable JSON ({exc})") from None


def _intrinsics(data: Any, where: str) -> Intrinsics:
    if not isinstance(data, dict):
        raise ValueError(f"{where}: intrinsics must be an object with width, height, fx, fy, cx, cy")
    try:
        values = {k: data[k] for k in ("width", "height", "fx", "fy", "cx", "cy")}
    except KeyError as exc:
        raise ValueError(f"{where}: intrinsics lack {exc}") from None
    if not all(isinstance(v, int | float) and not isinstance(v, bool) and math.isfinite(v) for v in values.values()):
        raise ValueError(f"{where}: intrinsics must be finite numbers")
    try:
        return Intrinsics(**values)
    except ValueError as exc:
        raise ValueError(f"{where}: {exc}") from None


def _inside(folder: Path, path: Path) -> bool:
    """``path`` is a regular file whose real location is inside ``folder`` (no symlink escapes)."""
    try:
        return path.is_file() and path.resolve().is_relative_to(folder.resolve())
    except OSError:
        return False


def load_recording(folder: str | Path) -> list[DepthFrame]:
    """The views of a recording folder as DepthFrames, in name order.

    Each view is ``NAME.json`` (``{"T_world_camera": {"position", "wxyz"}, "points_frame": "world" | "camera",
    "intrinsics": {...}}``, intrinsics optional when ``intrinsics.json`` exists) next to ``NAME.ply``
    (x, y, z). The points become a depth image with ``DepthFrame.from_points``. ValueError names the
    file for a missing partner, bad JSON, a bad pose, non-finite points or a view with no point in front
    of its camera.
    """
    folder = Path(folder)
    if not folder.is_dir():
        raise ValueError(f"recording {folder.name!r}: not a folder")
    default = None
    k_path = folder / "intrinsics.json"
    if _inside(folder, k_path):
        default = _intrinsics(_read_json(k_path), k_path.name)
    metas = sorted(p for p in folder.glob("*.json") if p.name != "intrinsics.json" and _inside(folder, p))
    if not metas:
        raise ValueError(f"recording {folder.name!r}: no views (expected NAME.ply + NAME.json pairs)")
    if len(metas) > MAX_VIEWS:
        raise ValueError(f"recording {folder.name!r}: {len(metas)} views, more than {MAX_VIEWS}")
    frames = []
    for meta_path in metas:
        ply = meta_path.with_suffix(".ply")
        if not _inside(folder, ply):
            raise ValueError(f"{meta_path.name}: no {ply.name} next to it")
        meta = _read_json(meta_path)
        if not isinstance(meta, dict) or not isinstance(meta.get("T_world_camera"), dict):
            raise ValueError(f"{meta_path.name}: needs a 'T_world_camera' object with position and wxyz")
        try:
            pose = Pose.from_dict(meta["T_world_camera"])
        except ValueError as exc:
            raise ValueError(f"{meta_path.name}: T_world_camera: {exc}") from None
        k = _intrinsics(meta["intrinsics"], meta_path.name) if "intrinsics" in meta else default
        if k is None:
            raise ValueError(f"{meta_path.name}: no intrinsics (give them here or in intrinsics.json)")
        points_frame = meta.get("points_frame", "world")
        if points_frame not in ("world", "camera"):
            raise ValueError(f"{meta_path.name}: points_frame must be 'world' or 'camera', got {points_frame!r}")
        points = read_ply(ply)  # ValueError for non-finite coordinates, with the file name
        if points_frame == "camera":
            points = pose.apply(points)
        frame = DepthFrame.from_points(points, pose, k)
        if not np.any(frame.valid):
            raise ValueError(f"{ply.name}: empty view (no point in front of the camera inside the image)")
        frames.append(frame)
    return frames
