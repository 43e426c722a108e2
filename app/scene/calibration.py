"""A calibration in the 3D view of a tab: the plate, the target, every pose's camera and the arm.

A tab opens a viewer of a calibration (``POST /api/calibrations/{id}/viewer``, a ticket like a session's); when it
connects, :class:`CalibrationViews` (one of the scene controller's ``other_viewers``) draws into that client's own
scene, in the table frame as a session's view:

- ``/calibration/plate``, ``/calibration/target``: the turntable and the sphere target as built;
- ``/calibration/poses/<i>``: each pose's camera frustum, grey pending, green captured, red skipped, orange the
  one previewed; ``/calibration/centres``: the sphere centres of the latest estimate;
- ``/robot/...`` (app/scene/robot.py): the arm where it stands, and the ghost playing a previewed move.

The calibration's events (selected, captured, skipped, estimate) redraw what changed in every tab showing it.
"""

from __future__ import annotations

import math
import threading
from typing import Any

import numpy as np
import viser

from app.scene.arm import shared_urdf
from app.scene.robot import RobotScene
from workbench import CalibrationRun, Calibrations, PosePreview, WorkbenchError

COLORS = {
    "pending": (150, 150, 160),
    "captured": (20, 150, 70),
    "skipped": (200, 40, 30),
    "selected": (255, 150, 0),
    "plate": (120, 120, 130),
    "target": (235, 225, 205),
    "centres": (40, 90, 220),
}


class _Tab:
    def __init__(self, client: viser.ClientHandle, robot: RobotScene | None) -> None:
        self.client = client
        self.robot = robot
        self.drawn: dict[int, tuple[str, bool]] = {}
        """pose index -> (colour key, previewed) as drawn (only changes are sent)."""


class CalibrationViews:
    """The tabs showing calibrations of ``calibrations``, hooked into ``controller`` (a SceneController)."""

    PREFIX = "cal-"

    def __init__(self, controller: Any, calibrations: Calibrations) -> None:
        self.calibrations = calibrations
        self._lock = threading.RLock()
        self._tabs: dict[str, list[_Tab]] = {}
        self._watched: set[str] = set()
        controller.other_viewers.append(self.attach)
        controller.server.on_client_disconnect(self._gone)

    def attach(self, client: viser.ClientHandle, key: str) -> bool:
        """Draw calibration ``key`` into ``client``'s scene; False when ``key`` is not an open calibration's."""
        if not key.startswith(self.PREFIX):
            return False
        try:
            run = self.calibrations.get(key)
        except WorkbenchError:
            return False
        cell = run.cell
        scene = client.scene
        r = float(cell.config.plate_radius)
        scene.add_cylinder(
            "/calibration/plate", radius=r, height=0.01, color=COLORS["plate"], radial_segments=48,
            position=(0.0, 0.0, -0.0051), cast_shadow=False, receive_shadow=False,
        )  # fmt: skip
        mesh = run.routine.target.mesh(subdivisions=3)
        scene.add_mesh_simple(
            "/calibration/target", np.asarray(mesh.vertices, np.float32), np.asarray(mesh.faces, np.int32),
            color=COLORS["target"],
        )  # fmt: skip
        scene.add_label("/calibration/label", f"calibration {run.id}", position=(0.0, -1.1 * r, 0.0))
        robot = None
        if cell.kinematics is not None:
            model = cell.kinematics.model
            robot = RobotScene(client, model, urdf=shared_urdf(model))
            robot.show(cell.arm.joint_positions(), cell.angle)
        tab = _Tab(client, robot)
        with self._lock:
            self._tabs.setdefault(run.id, []).append(tab)
            if run.id not in self._watched:
                self._watched.add(run.id)
                run.listeners.append(self._on_event)
        self._draw_poses(run, tab)
        preview = None if run.selected is None else run.preview_of(run.selected)
        self._show_preview(tab, preview)
        return True

    def _gone(self, client: viser.ClientHandle) -> None:
        with self._lock:
            for key, tabs in self._tabs.items():
                for tab in [t for t in tabs if t.client is client]:
                    if tab.robot is not None:
                        tab.robot.stop()
                    tabs.remove(tab)
                if not tabs:
                    self._tabs[key] = []

    def tabs_of(self, run: CalibrationRun) -> list[_Tab]:
        with self._lock:
            return list(self._tabs.get(run.id, []))

    # ------------------------------------------------------------------ drawing

    def _draw_poses(self, run: CalibrationRun, tab: _Tab) -> None:
        status = run.status()
        k = run.cell.camera.intrinsics
        fov = 2 * math.atan2(k.height / 2, k.fy)
        for pose, state in zip(run.routine.poses, status["poses"], strict=True):
            i = state["index"]
            key = (state["status"], status["selected"] == i)
            if tab.drawn.get(i) == key:
                continue
            color = COLORS["selected"] if key[1] else COLORS[state["status"]]
            T = pose.T_table_camera
            tab.client.scene.add_camera_frustum(
                f"/calibration/poses/{i}", fov=fov, aspect=k.width / k.height, scale=0.04, color=color,
                wxyz=T.wxyz, position=T.translation, thickness=0.003 if key[1] else 0.0015,
                variant="filled" if key[1] or state["status"] == "captured" else "wireframe",
            )  # fmt: skip
            tab.drawn[i] = key
        result = run.result
        if result is not None:
            tab.client.scene.add_point_cloud(
                "/calibration/centres", np.asarray(result.centres_table, np.float32), colors=COLORS["centres"],
                point_size=0.012, point_shape="circle",
            )  # fmt: skip

    @staticmethod
    def _show_preview(tab: _Tab, preview: PosePreview | None, animate: bool = False) -> None:
        robot = tab.robot
        if robot is None:
            return
        motion = None if preview is None else preview.motion
        if motion is None or motion.q is None:
            robot.show_ghost(None)
            robot.show_path(None)
            return
        robot.show_ghost(motion.q, motion.angle)
        robot.show_path(motion.trajectory, motion.angle)
        if animate and motion.trajectory is not None:
            robot.animate(motion.trajectory, motion.angle, ghost=True)

    def _on_event(self, run: CalibrationRun, event: str) -> None:
        tabs = self.tabs_of(run)
        for tab in tabs:
            self._draw_poses(run, tab)
            if event in ("captured", "skipped") and tab.robot is not None:
                tab.robot.stop()
                tab.robot.show_ghost(None)
                tab.robot.show_path(None)
                tab.robot.show(run.cell.arm.joint_positions(), run.cell.angle)
            elif event == "selected":
                self._show_preview(tab, None if run.selected is None else run.preview_of(run.selected))

    def play_preview(self, run: CalibrationRun, preview: PosePreview) -> int:
        """Play ``preview``'s move on the ghost in every tab showing ``run``; the number of tabs."""
        tabs = self.tabs_of(run)
        for tab in tabs:
            self._show_preview(tab, preview, animate=True)
        return len(tabs)
