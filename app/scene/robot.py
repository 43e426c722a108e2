"""The arm in the 3D view: drawn from its meshes at a configuration, a translucent ghost at a target, the camera's
path, and a trajectory animated, in a viser scene (a ``ViserServer`` or one tab's ``ClientHandle``).

The scene shows the planner's world, the table frame; the arm stands in the base frame, so its root is drawn at
``Rz(-theta) @ T_base_mount`` for the plate angle theta (turning the plate turns the arm around the object in
this view). Nodes (stable names, under ``root``, ``/robot`` by default):

- ``/robot/arm``: the arm at its configuration (:meth:`RobotScene.show`);
- ``/robot/ghost``: the arm at a target, translucent (:meth:`RobotScene.show_ghost`; hidden with ``None``);
- ``/robot/path``: the camera's path along a trajectory, a polyline (:meth:`RobotScene.show_path`).

:meth:`RobotScene.animate` plays a :class:`devices.trajectory.JointTrajectory` on the arm (or the ghost, for a
preview before approval) in a thread; it returns at once and ``stop()`` ends it. app/scene/arm.py wires it into the per-tab scenes.
"""

from __future__ import annotations

import math
import threading
import time
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import NDArray

from app.scene.lighting import configure_lighting
from devices.arm.model import ArmModel
from devices.trajectory import JointTrajectory
from planner.types import Pose

GHOST_COLOR = (0.45, 0.7, 1.0, 0.18)
"""RGBA of the ghost arm at a target: faint translucent blue (it must not hide the object in front of it)."""
PATH_COLOR = (255, 170, 0)
"""RGB of the camera's path."""
FRAME_SECONDS = 1 / 30
"""Animation frame period, seconds."""


def load_urdf_for_viser(arm: ArmModel) -> Any:
    """The arm's URDF as a ``yourdfpy.URDF`` with its meshes, ``package://`` paths looked up in ``arm.package_dirs``."""
    import yourdfpy

    dirs = [Path(d) for d in arm.package_dirs]

    def handler(fname: str) -> str:
        filename = fname
        if filename.startswith("package://"):
            relative = filename[len("package://") :]
            for d in dirs:
                if (d / relative).is_file():
                    return str(d / relative)
            return str(dirs[0] / relative) if dirs else relative
        path = Path(filename)
        return str(path if path.is_absolute() else arm.urdf_path.parent / path)

    return yourdfpy.URDF.load(str(arm.urdf_path), filename_handler=handler, load_meshes=True, build_scene_graph=True)


def _wxyz(R: NDArray[np.float64]) -> tuple[float, float, float, float]:
    from scipy.spatial.transform import Rotation

    x, y, z, w = Rotation.from_matrix(R).as_quat()
    return (float(w), float(x), float(y), float(z))


class RobotScene:
    """The arm of ``arm`` drawn into ``target`` (a ``viser.ViserServer`` or ``viser.ClientHandle``) under ``root``.

    urdf: a preloaded ``yourdfpy.URDF`` (loading the meshes takes a second; share one between tabs), or None.
    """

    def __init__(self, target: Any, arm: ArmModel, *, root: str = "/robot", urdf: Any | None = None) -> None:
        from viser.extras import ViserUrdf

        self.target = target
        self.arm = arm
        self.root = root
        model: Any = urdf if urdf is not None else load_urdf_for_viser(arm)
        self._frames = {name: target.scene.add_frame(f"{root}/{name}", show_axes=False) for name in ("arm", "ghost")}
        self._arm = ViserUrdf(target, model, root_node_name=f"{root}/arm")
        self._ghost = ViserUrdf(target, model, root_node_name=f"{root}/ghost", mesh_color_override=GHOST_COLOR)
        self._frames["ghost"].visible = False
        self._path: Any = None
        self._lock = threading.Lock()
        self._stop = threading.Event()
        self._thread: threading.Thread | None = None
        self.q: NDArray[np.float64] = np.zeros(arm.nq)
        self.angle = 0.0

    # ------------------------------------------------------------------ drawing

    def _place(self, name: str, angle: float) -> None:
        """Put the arm's root at ``Rz(-angle) @ T_base_mount`` (the table frame of the view)."""
        c, s = math.cos(-angle), math.sin(-angle)
        Rz = np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])
        mount = self.arm.T_base_mount
        frame = self._frames[name]
        frame.position = tuple(float(v) for v in Rz @ mount.translation)
        frame.wxyz = _wxyz(Rz @ mount.rotation)

    def _cfg(self, q: NDArray[np.float64]) -> NDArray[np.float64]:
        q = np.asarray(q, dtype=np.float64)
        if q.shape != (self.arm.nq,) or not np.all(np.isfinite(q)):
            raise ValueError(f"q: expected ({self.arm.nq},) finite joint positions, got shape {q.shape}")
        return q

    def show(self, q: NDArray[np.float64], angle: float) -> None:
        """The arm at configuration (n,) ``q`` with the plate at ``angle`` (rad)."""
        q = self._cfg(q)
        with self._lock:
            self.q, self.angle = q.copy(), float(angle)
            self._place("arm", angle)
            self._arm.update_cfg(q)

    def show_ghost(self, q: NDArray[np.float64] | None, angle: float = 0.0) -> None:
        """The translucent arm at a target (n,) ``q`` with the plate at ``angle``; None hides it."""
        if q is None:
            self._frames["ghost"].visible = False
            return
        q = self._cfg(q)
        self._place("ghost", angle)
        self._ghost.update_cfg(q)
        self._frames["ghost"].visible = True

    def camera_path(self, trajectory: JointTrajectory, angle: float) -> NDArray[np.float64]:
        """(K, 3) the camera's positions along ``trajectory`` in the table frame (plate at ``angle``)."""
        data = self.arm.model.createData()
        c, s = math.cos(-angle), math.sin(-angle)
        Rz = np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])
        return np.array([Rz @ self.arm.camera_pose(q, data).translation for q in trajectory.positions])

    def show_path(self, trajectory: JointTrajectory | None, angle: float = 0.0) -> NDArray[np.float64] | None:
        """The camera's path along ``trajectory`` as a polyline (None removes it); returns the (K, 3) points."""
        if self._path is not None:
            self._path.remove()
            self._path = None
        if trajectory is None:
            return None
        points = self.camera_path(trajectory, angle)
        if len(points) < 2:
            points = np.vstack([points, points])
        segments = np.stack([points[:-1], points[1:]], axis=1).astype(np.float32)
        self._path = self.target.scene.add_line_segments(
            f"{self.root}/path", points=segments, colors=PATH_COLOR, thickness=3.0, thickness_units="screen"
        )
        return points

    def node_names(self) -> list[str]:
        """The arm's top nodes now in the scene: ``/robot/arm``, and ``/robot/ghost`` / ``/robot/path`` when shown."""
        names = [f"{self.root}/arm"]
        if self._frames["ghost"].visible:
            names.append(f"{self.root}/ghost")
        if self._path is not None:
            names.append(f"{self.root}/path")
        return names

    @property
    def animating(self) -> bool:
        """Whether an animation is playing."""
        thread = self._thread
        return thread is not None and thread.is_alive()

    # ------------------------------------------------------------------ animation

    def animate(
        self,
        trajectory: JointTrajectory,
        angle: float,
        *,
        ghost: bool = False,
        speed: float = 1.0,
        on_done: Any = None,
    ) -> threading.Thread:
        """Play ``trajectory`` on the arm (or on the ghost: a preview) at ``speed`` x real time, in a thread.

        A running animation is stopped first. ``on_done()`` is called at the end (not when stopped).
        """
        if not (math.isfinite(speed) and speed > 0):
            raise ValueError(f"speed: must be > 0, got {speed!r}")
        if trajectory.joint_names != self.arm.joint_names:
            raise ValueError(f"trajectory: joints {trajectory.joint_names} are not the arm's {self.arm.joint_names}")
        self.stop()
        self._stop.clear()

        def run() -> None:
            t0 = time.monotonic()
            while not self._stop.is_set():
                t = (time.monotonic() - t0) * speed
                q = trajectory.sample(t)
                if ghost:
                    self.show_ghost(q, angle)
                else:
                    self.show(q, angle)
                if t >= trajectory.duration:
                    if on_done is not None:
                        on_done()
                    return
                self._stop.wait(FRAME_SECONDS)

        self._thread = threading.Thread(target=run, name="robot-animation", daemon=True)
        self._thread.start()
        return self._thread

    def stop(self) -> None:
        """End a running animation (the arm stays where it was drawn last)."""
        self._stop.set()
        thread = self._thread
        if thread is not None and thread is not threading.current_thread():
            thread.join(timeout=2.0)
        self._thread = None

    def remove(self) -> None:
        """Remove every node of the arm from the scene: the two top frames, and with them (viser removes a node's
        descendants) the URDF's links and meshes drawn under them. ``ViserUrdf.remove`` would remove each joint
        frame and then each mesh, which the frames had taken along already: a warning per mesh."""
        self.stop()
        self.show_path(None)
        for frame in self._frames.values():
            frame.remove()


def ghost_pose(arm: ArmModel, q: NDArray[np.float64], angle: float) -> Pose:
    """``T_table_camera`` of the ghost at (n,) ``q`` with the plate at ``angle``: where the view will be taken."""
    c, s = math.cos(-angle), math.sin(-angle)
    Rz = np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])
    T = arm.camera_pose(q)
    return Pose(Rz @ T.rotation, Rz @ T.translation)


def demo(port: int = 0, model: str = "mug") -> tuple[Any, RobotScene, Any]:
    """A viser server showing the UR5 cell: ``model`` (a built-in name or a mesh path) on the plate, the arm at its
    first view, the ghost and the camera path of the move to another view. Returns (server, scene, motion)."""
    import viser

    from devices.builtins import resolve_model
    from devices.sim import make_sim_cell

    _, mesh = resolve_model(model, up="y", size=0.2)
    cell = make_sim_cell(mesh)
    assert cell.kinematics is not None
    server = viser.ViserServer(host="127.0.0.1", port=port)
    configure_lighting(server)
    server.scene.add_mesh_simple(
        "/object", np.asarray(mesh.vertices, np.float32), np.asarray(mesh.faces), color=(200, 190, 170)
    )
    server.scene.add_mesh_simple(
        "/plate", *_plate(cell.config.plate_radius, cell.config.plate_thickness), color=(120, 120, 130)
    )
    robot = RobotScene(server, cell.kinematics.model)
    robot.show(cell.arm.joint_positions(), cell.angle)
    e, a = math.radians(35.0), math.radians(70.0)
    target = Pose.look_at(
        0.45 * np.array([math.cos(e) * math.cos(a), math.cos(e) * math.sin(a), math.sin(e)]) + [0, 0, 0.1], [0, 0, 0.1]
    )
    motion = cell.plan_motion(target)
    assert motion.q is not None and motion.trajectory is not None
    robot.show_ghost(motion.q, motion.angle)
    robot.show_path(motion.trajectory, motion.angle)  # the arm moves once the plate has turned
    return server, robot, motion


def _plate(radius: float, thickness: float) -> tuple[NDArray[np.float32], NDArray[np.int32]]:
    import trimesh

    plate = trimesh.creation.cylinder(radius=radius, height=thickness, sections=64)
    plate.apply_translation((0.0, 0.0, -0.5 * thickness))
    return np.asarray(plate.vertices, np.float32), np.asarray(plate.faces, np.int32)


def screenshot(out: str, model: str) -> None:
    """Save a PNG of :func:`demo` from headless Chromium (the docs' picture of the arm)."""
    from playwright.sync_api import sync_playwright

    server, _, _ = demo(0, model)

    @server.on_client_connect
    def _(client: Any) -> None:
        client.camera.position = (0.05, -1.15, 0.62)
        client.camera.look_at = (-0.12, 0.12, 0.16)

    args = ["--headless", "--no-sandbox", "--use-gl=angle", "--use-angle=swiftshader", "--enable-unsafe-swiftshader"]
    with sync_playwright() as p:
        browser = p.chromium.launch(executable_path="/usr/bin/chromium", args=args)
        page = browser.new_page(viewport={"width": 1200, "height": 800})
        page.goto(f"http://127.0.0.1:{server.get_port()}/")
        time.sleep(12.0)  # SwiftShader: meshes load and render
        for label in ("button.mantine-Notification-closeButton",):
            if page.locator(label).count():
                page.locator(label).first.click()
        time.sleep(1.0)
        page.screenshot(path=out)
        browser.close()
    server.stop()


if __name__ == "__main__":
    import sys

    screenshot(sys.argv[1] if len(sys.argv) > 1 else "docs/arm.png", sys.argv[2] if len(sys.argv) > 2 else "mug")
