"""The first screen's 3D view: the simulated cell and the server's default object, before any session exists.

A tab with no session open asks for a *preview* viewer (``POST /api/viewer/preview``, a ticket like a session's
with the key :data:`PREVIEW_KEY`); when it connects, :class:`PreviewViews` (one of the scene controller's
``other_viewers``) draws into that client's own scene what the demo scan would start from:

- ``/preview/turntable``: the plate; ``/preview/object``: the default model placed on it (opaque);
- ``/preview/label``: which object, and that no session is open yet;
- ``/robot/arm/...`` (app/scene/robot.py): the arm where the demo's cell builds it (at its first view's pose,
  the pose nearest its home), the plate turned as it will be.

No session is created and nothing is journaled. The geometry (the placed mesh, simplified to
:data:`PREVIEW_TRIANGLES`; the cell's arm model, joints and plate angle) is computed once per server, on the first
preview, and shared by every tab; a tab costs only the messages of its own scene. Opening a session loads the session's page, whose viewer replaces this one.
"""

from __future__ import annotations

import logging
import math
import threading
from dataclasses import dataclass
from typing import Any

import numpy as np
import viser
from numpy.typing import NDArray

from app.scene.arm import shared_urdf
from app.scene.camera import FRAMING_FOV_DEG, framing
from app.scene.geometry import COLORS
from app.scene.robot import RobotScene
from devices.arm.model import ArmModel
from workbench import WorkbenchError, WorkbenchSettings

log = logging.getLogger(__name__)

PREVIEW_KEY = "preview"
"""The key a preview viewer's ticket carries (never a session's id: those are 8 hex digits)."""
PREVIEW_TRIANGLES = 15_000
"""The object's triangle budget in the preview (quadric decimation, once per server): a 70 000-triangle scan sent
whole is 1.3 MB per tab, 40 MB for a class of 30; at this budget about 0.3 MB."""
INITIAL_EYE = np.asarray(framing(None)[0], dtype=float)
"""Where viser's client puts a new camera (the server's initial camera, app/scene/controller.py)."""


@dataclass(frozen=True, eq=False)
class PreviewGeometry:
    """What every preview tab draws, computed once.

    model: the default model's name; vertices (V, 3) float32 and faces (F, 3) uint32: its mesh placed on the
    plate (table frame, metres; at most :data:`PREVIEW_TRIANGLES` faces); plate_radius: metres; arm: the cell's arm model (None for a cell without one);
    q: (n,) its joints, angle: the plate's angle (rad), mount_xy: the arm's mount in the view's frame (metres)."""

    model: str
    vertices: NDArray[np.float32]
    faces: NDArray[np.uint32]
    plate_radius: float
    arm: ArmModel | None
    q: NDArray[np.float64] | None
    angle: float
    mount_xy: tuple[float, float] | None


def build_geometry(settings: WorkbenchSettings) -> PreviewGeometry:
    """The default model placed on the plate and the cell the demo scan builds for it (``settings.devices``:
    its camera and cell; seed 0). NotFound / Invalid for a default model that does not load."""
    from devices.sim import make_sim_cell
    from workbench import load_model
    from workbench.surface import SurfaceMesh, simplify

    name = settings.devices.model
    mesh = load_model(settings, name)
    cell = make_sim_cell(mesh, settings.devices.camera, settings.devices.cell, seed=0)
    arm = q = mount_xy = None
    angle = float(cell.angle)
    if cell.kinematics is not None:
        arm = cell.kinematics.model
        q = np.asarray(cell.arm.joint_positions(), dtype=np.float64)
        t = np.asarray(arm.T_base_mount.translation, dtype=float)
        c, s = math.cos(-angle), math.sin(-angle)
        mount_xy = (c * t[0] - s * t[1], s * t[0] + c * t[1])
    shown = simplify(SurfaceMesh.canonical(np.asarray(mesh.vertices), np.asarray(mesh.faces)), PREVIEW_TRIANGLES)
    return PreviewGeometry(
        model=name,
        vertices=np.asarray(shown.vertices, dtype=np.float32),
        faces=np.asarray(shown.faces, dtype=np.uint32),
        plate_radius=float(settings.devices.cell.plate_radius),
        arm=arm,
        q=q,
        angle=angle,
        mount_xy=mount_xy,
    )


class PreviewViews:
    """The tabs showing the preview, hooked into ``controller`` (a SceneController); ``settings``: the server's."""

    def __init__(self, controller: Any, settings: WorkbenchSettings) -> None:
        self.settings = settings
        self._lock = threading.Lock()
        self._build = threading.Lock()  # held while the geometry is built: the other tabs wait for it
        self._geometry: PreviewGeometry | None = None
        self._robots: dict[int, RobotScene] = {}
        self.builds = 0
        """How many times the geometry was built (once per server)."""
        controller.other_viewers.append(self.attach)
        controller.server.on_client_disconnect(self._gone)

    def geometry(self) -> PreviewGeometry:
        """The shared geometry, built on first use."""
        with self._build:
            if self._geometry is None:
                self._geometry = build_geometry(self.settings)
                self.builds += 1
            return self._geometry

    def attach(self, client: viser.ClientHandle, key: str) -> bool:
        """Draw the preview into ``client``'s scene when ``key`` is :data:`PREVIEW_KEY`; False otherwise."""
        if key != PREVIEW_KEY:
            return False
        try:
            g = self.geometry()
        except (WorkbenchError, ValueError) as exc:
            log.warning("the first screen's 3D view: the default model does not load: %s", exc)
            return True  # a preview still (an empty scene), never a session's
        scene = client.scene
        r = g.plate_radius
        with client.atomic():
            scene.add_cylinder(
                "/preview/turntable", radius=r, height=0.01, color=COLORS["plate"], radial_segments=48,
                position=(0.0, 0.0, -0.0051), cast_shadow=False, receive_shadow=False,
            )  # fmt: skip
            scene.add_mesh_simple(
                "/preview/object", g.vertices, g.faces, color=COLORS["mesh"], cast_shadow=False, receive_shadow=False,
            )  # fmt: skip
            scene.add_label(
                "/preview/label", f"{g.model} · no session yet", position=(0.0, -1.1 * r, 0.0), font_screen_scale=0.6
            )
        if g.arm is not None and g.q is not None:
            robot = RobotScene(client, g.arm, urdf=shared_urdf(g.arm))
            robot.show(g.q, g.angle)
            with self._lock:
                self._robots[client.client_id] = robot
        self._frame(client, g)
        return True

    @staticmethod
    def _frame(client: viser.ClientHandle, g: PreviewGeometry) -> None:
        """Point ``client``'s camera at the object from the side away from the arm (as a session's view starts),
        again when viser's client first draws and puts its camera at the server's initial one."""
        eye, look_at = framing(g.mount_xy)

        def put() -> None:
            with client.atomic():
                client.camera.up_direction = (0.0, 0.0, 1.0)
                client.camera.position = np.asarray(eye, dtype=float)
                client.camera.look_at = np.asarray(look_at, dtype=float)
                client.camera.fov = math.radians(FRAMING_FOV_DEG)

        put()

        @client.camera.on_update
        def _(camera: Any) -> None:
            at = np.asarray(camera.position, dtype=float)
            if np.linalg.norm(at - INITIAL_EYE) < 1e-3 and np.linalg.norm(at - np.asarray(eye)) > 1e-3:
                put()

    def _gone(self, client: viser.ClientHandle) -> None:
        with self._lock:
            robot = self._robots.pop(client.client_id, None)
        if robot is not None:
            robot.stop()

    def tabs(self) -> int:
        """How many connected tabs show the preview's arm."""
        with self._lock:
            return len(self._robots)
