"""The viser scene: a listener that draws the focused session from its PlanResult.

One viser server serves every browser; it shows one session at a time (the
*focused* one, chosen with ``PUT /api/scene``). The controller subscribes to that
Session's events and redraws what changed, always inside ``server.atomic()``
and under one lock, under stable node names::

    /map/occupied /map/frontier /map/unknown /map/empty      voxel centres (point clouds)
    /ellipsoids/occupied/3, /ellipsoids/frontier/0          MVEEs (translucent)
    /gmm/frontier/0                                          2-sigma GMM covariances (debug)
    /candidates                                              one batched mesh, clickable
    /nbv, /selected                                          the planner's choice, the selection
    /views/7/frustum, /views/7/label                         views taken
    /context/bbox /context/sectors /context/turntable /context/mesh
    /cloud                                                   accumulated registered cloud
    /override/gizmo (+ /override/gizmo/frustum)              custom-pose transform gizmo

Every layer can be hidden (``set_layers``); GUI callbacks (a click on a
candidate, a gizmo drag) call the Session, never the planner.
"""

from __future__ import annotations

import logging
import math
import threading
from typing import Any

import numpy as np
import trimesh
import viser

from app.scene.camera import client_cameras, set_camera
from app.scene.geometry import (
    COLORS,
    DEFAULT_LAYERS,
    GROUPS,
    LAYER_NODES,
    VIRIDIS,
    box_segments,
    candidate_colors,
    ellipsoid_instance,
    gmm_instance,
    outward_camera,
    sector_label_positions,
    sector_segments,
)
from planner import Pose
from workbench.errors import Conflict, Invalid, NotFound, WorkbenchError
from workbench.session import Session
from workbench.states import SceneData

log = logging.getLogger(__name__)

_MARKER = trimesh.creation.icosphere(subdivisions=1, radius=1.0)


class SceneController:
    """Draws the focused session into a viser server; thread-safe."""

    def __init__(self, server: viser.ViserServer) -> None:
        self.server = server
        self.layers = dict(DEFAULT_LAYERS)
        self.score_range = (0.0, 1.0)
        self._lock = threading.RLock()
        self._handles: dict[str, viser.SceneNodeHandle] = {}
        self._session: Session | None = None
        self._data: SceneData | None = None
        server.scene.set_up_direction("+z")
        server.scene.configure_default_lights(enabled=True, cast_shadow=False)
        server.initial_camera.position = (0.95, -0.8, 0.75)
        server.initial_camera.look_at = (0.0, 0.0, 0.08)
        server.initial_camera.near = 0.01
        server.gui.configure_theme(show_share_button=False, show_logo=False)
        server.gui.main_panel.minimize()
        with self._lock, server.atomic():
            self._groups()

    # ------------------------------------------------------------------ focus and events

    @property
    def session(self) -> Session | None:
        return self._session

    def focus(self, wb: Session | None) -> None:
        """Show ``wb`` (None: an empty scene) and follow its events."""
        with self._lock:
            old = self._session
            if old is not None and self._on_event in old.listeners:
                old.listeners.remove(self._on_event)
            self._session = wb
            if wb is not None:
                wb.listeners.append(self._on_event)
            self._clear()
            if wb is not None:
                self._redraw(wb.scene_data(), "all")

    def _on_event(self, wb: Session, event: str) -> None:
        if wb is not self._session or event == "state":
            return
        self._redraw(wb.scene_data(), event)

    def _redraw(self, data: SceneData, event: str) -> None:
        with self._lock, self.server.atomic():
            self._data = data
            if event in ("all", "planned"):
                self._draw_plan(data)
            if event in ("all", "planned", "captured"):
                self._draw_views(data)
                self._draw_cloud(data)
            if event == "all":
                self._draw_context(data)
            if event in ("all", "planned", "captured", "selection"):
                self._draw_selection(data)
                self._draw_gizmo(data)
            if event == "custom_pose":
                self._draw_gizmo_frustum(data)

    # ------------------------------------------------------------------ layers

    def set_layers(self, changes: dict[str, bool]) -> dict[str, bool]:
        """Show / hide layers by name; ValueError for an unknown name (nothing changes then)."""
        unknown = set(changes) - set(self.layers)
        if unknown:
            raise Invalid(f"layers: unknown {sorted(unknown)} (known: {', '.join(self.layers)})")
        with self._lock, self.server.atomic():
            self.layers.update({k: bool(v) for k, v in changes.items()})
            for layer in changes:
                for name in LAYER_NODES[layer]:
                    handle = self._handles.get(name)
                    if handle is not None:
                        handle.visible = self.layers[layer]
            if "gizmo" in changes and self._data is not None:
                self._draw_gizmo(self._data)
            return dict(self.layers)

    def node_names(self) -> list[str]:
        with self._lock:
            return sorted(self._handles)

    def info(self) -> dict[str, Any]:
        """Focused session, layers, drawn node names and the colour bar (stops and score range)."""
        with self._lock:
            return {
                "session": None if self._session is None else self._session.id,
                "layers": dict(self.layers),
                "nodes": sorted(self._handles),
                "colormap": [list(c) for c in VIRIDIS],
                "score_range": list(self.score_range),
            }

    # ------------------------------------------------------------------ camera

    def look_at_candidate(self, index: int, distance: float = 0.3) -> int:
        """Point every connected client's camera at candidate ``index`` from outside the hemisphere.

        Returns the number of clients moved. Conflict without a plan, NotFound for a bad index.
        """
        with self._lock:
            data = self._data
            if data is None or data.plan is None:
                raise Conflict("no plan is drawn")
            if not 0 <= index < len(data.plan.candidates):
                raise NotFound(f"candidate {index}: out of range")
            target = data.plan.candidates[index].position
            eye = outward_camera(target, data.plan.hemisphere_center, distance)
        return self.set_camera(eye, target)

    def set_camera(self, position: Any, look_at: Any) -> int:
        """Move every connected client's camera (and the initial camera of later ones)."""
        return set_camera(self.server, position, look_at)

    def cameras(self) -> list[dict[str, Any]]:
        """The camera each connected client reported last (OpenCV pose, vertical fov, canvas size)."""
        return client_cameras(self.server)

    # ------------------------------------------------------------------ drawing helpers (lock held)

    def _put(self, name: str, handle: viser.SceneNodeHandle) -> None:
        self._handles[name] = handle

    def _drop(self, prefix: str) -> None:
        """Remove the node ``prefix`` (if it is not a group) and every node below it."""
        for name in [n for n in self._handles if n.startswith(prefix + "/") or (n == prefix and n not in GROUPS)]:
            handle = self._handles.pop(name)
            if not handle._impl.removed:
                handle.remove()

    def _groups(self) -> None:
        for name, layer in GROUPS.items():
            visible = True if layer is None else self.layers[layer]
            self._put(name, self.server.scene.add_frame(name, show_axes=False, visible=visible))

    def _clear(self) -> None:
        for name in [n for n in self._handles if n not in GROUPS]:
            self._drop(name)
        self._data = None

    def _visible(self, layer: str) -> bool:
        return self.layers[layer]

    # ------------------------------------------------------------------ drawing

    def _draw_plan(self, data: SceneData) -> None:
        scene = self.server.scene
        plan = data.plan
        for name in ("/map", "/ellipsoids", "/gmm", "/candidates", "/context/bbox", "/context/sectors"):
            self._drop(name)
        if plan is None:
            return
        vox = plan.voxels
        sizes = {"occupied": 0.9, "frontier": 0.9, "unknown": 0.35, "empty": 0.3}
        for kind, size in sizes.items():
            pts = np.asarray(getattr(vox, kind), dtype=np.float32).reshape(-1, 3)
            name = f"/map/{kind}"
            handle = scene.add_point_cloud(
                name, pts, COLORS[kind], point_size=size * vox.resolution, precision="float32",
                point_shape="square", point_shading="flat", visible=self._visible(kind),
            )  # fmt: skip
            self._put(name, handle)
        counts = {"occupied": 0, "frontier": 0}
        for e in plan.ellipsoids:
            i = counts[e.kind]
            counts[e.kind] += 1
            wxyz, pos, axes = ellipsoid_instance(e)
            name = f"/ellipsoids/{e.kind}/{i}"
            self._put(name, scene.add_icosphere(
                name, 1.0, COLORS[f"ellipsoid_{e.kind}"], subdivisions=2, scale=tuple(axes), opacity=0.3,
                wxyz=wxyz, position=pos, cast_shadow=False, receive_shadow=False, side="double",
            ))  # fmt: skip
            gmm = gmm_instance(e)
            if gmm is not None:
                gname = f"/gmm/{e.kind}/{i}"
                self._put(gname, scene.add_icosphere(
                    gname, 1.0, COLORS[f"gmm_{e.kind}"], subdivisions=1, scale=tuple(gmm[2]), wireframe=True,
                    wxyz=gmm[0], position=gmm[1], cast_shadow=False, receive_shadow=False,
                ))  # fmt: skip
        self._draw_candidates(data)
        self._put("/context/bbox", scene.add_line_segments(
            "/context/bbox", box_segments(plan.bbox), COLORS["bbox"], thickness=1.5, thickness_units="screen",
            visible=self._visible("bbox"),
        ))  # fmt: skip
        radius = plan.hemisphere_radius
        segs = sector_segments(plan.hemisphere_center, radius, plan.sector_edges)
        self._put("/context/sectors/lines", scene.add_line_segments(
            "/context/sectors/lines", segs, COLORS["sector"], thickness=2.0, thickness_units="screen",
        ))  # fmt: skip
        labels = sector_label_positions(plan.hemisphere_center, 0.9 * radius, plan.sector_edges)
        for k, pos in enumerate(labels):
            tag = "scanned" if k in plan.scanned_sectors else ("eligible" if k in plan.eligible_sectors else "locked")
            name = f"/context/sectors/{k}"
            self._put(name, scene.add_label(name, f"S{k} {tag}", position=pos, font_screen_scale=0.7))

    def _draw_candidates(self, data: SceneData) -> None:
        plan = data.plan
        assert plan is not None
        n = len(plan.candidates)
        if n == 0:
            return
        colors, lo, hi = candidate_colors([s.score for s in plan.scores], [s.eligible for s in plan.scores])
        self.score_range = (lo, hi)
        spacing = math.sqrt(2.0 * math.pi * plan.hemisphere_radius**2 / n)
        radius = 0.16 * spacing
        positions = np.stack([c.position for c in plan.candidates])
        handle = self.server.scene.add_batched_meshes_simple(
            "/candidates", _MARKER.vertices, _MARKER.faces,
            batched_wxyzs=np.tile([1.0, 0.0, 0.0, 0.0], (n, 1)), batched_positions=positions,
            batched_scales=np.full(n, radius), batched_colors=colors, lod="off",
            cast_shadow=False, receive_shadow=False, visible=self._visible("candidates"),
        )  # fmt: skip
        handle.on_click(self._on_candidate_click)
        self._put("/candidates", handle)

    def _on_candidate_click(self, event: viser.SceneNodePointerEvent) -> None:
        """A click on a candidate marker selects it in the Session (viser thread pool, no lock held)."""
        wb, data = self._session, self._data
        if wb is None or data is None or data.plan is None:
            return
        index = event.instance_index
        if index is None:  # fall back to the marker nearest the click ray
            o, d = np.asarray(event.ray_origin), np.asarray(event.ray_direction)
            p = np.stack([c.position for c in data.plan.candidates]) - o
            index = int(np.argmin(np.linalg.norm(p - np.outer(p @ d, d), axis=1)))
        try:
            wb.select(int(index))
        except WorkbenchError as exc:
            log.info("click on candidate %s ignored: %s", index, exc.detail)

    def _frustum(self, name: str, pose: Pose, data: SceneData, color: tuple[int, int, int], **kw: Any) -> None:
        self._put(name, self.server.scene.add_camera_frustum(
            name, fov=data.fov_y, aspect=data.aspect, color=color, wxyz=pose.wxyz, position=pose.translation,
            cast_shadow=False, receive_shadow=False, **kw,
        ))  # fmt: skip

    def _draw_selection(self, data: SceneData) -> None:
        self._drop("/nbv")
        self._drop("/selected")
        plan = data.plan
        if plan is None or data.plan_id is None:
            return
        visible = self._visible("nbv")
        if plan.best is not None:
            self._frustum("/nbv", plan.best.T_world_camera, data, COLORS["nbv"], scale=0.07, thickness=0.004,
                          visible=visible, variant="filled")  # fmt: skip
        if data.selected is not None and data.selected != plan.best_index:
            pose = plan.candidates[data.selected].T_world_camera
            self._frustum("/selected", pose, data, COLORS["selected"], scale=0.07, thickness=0.004,
                          visible=visible, variant="filled")  # fmt: skip

    def _draw_views(self, data: SceneData) -> None:
        self._drop("/views")
        for i, pose in enumerate(data.views, start=1):
            root = f"/views/{i}"
            self._put(
                root, self.server.scene.add_frame(root, show_axes=False, wxyz=pose.wxyz, position=pose.translation)
            )
            self._put(f"{root}/frustum", self.server.scene.add_camera_frustum(
                f"{root}/frustum", fov=data.fov_y, aspect=data.aspect, scale=0.045, thickness=0.002,
                color=COLORS["view"], cast_shadow=False, receive_shadow=False,
            ))  # fmt: skip
            self._put(f"{root}/label", self.server.scene.add_label(f"{root}/label", str(i), font_screen_scale=0.8))

    def _draw_cloud(self, data: SceneData) -> None:
        self._drop("/cloud")
        pts = np.asarray(data.cloud, dtype=np.float32).reshape(-1, 3)
        self._put("/cloud", self.server.scene.add_point_cloud(
            "/cloud", pts, COLORS["cloud"], point_size=0.002, precision="float32", point_shading="flat",
            visible=self._visible("cloud"),
        ))  # fmt: skip

    def _draw_context(self, data: SceneData) -> None:
        scene = self.server.scene
        self._drop("/context/turntable")
        self._drop("/context/mesh")
        self._put("/context/turntable", scene.add_cylinder(
            "/context/turntable", radius=data.plate_radius, height=0.01, color=COLORS["plate"], radial_segments=48,
            position=(0.0, 0.0, -0.0051), cast_shadow=False, receive_shadow=False, visible=self._visible("turntable"),
        ))  # fmt: skip
        mesh = data.mesh
        if len(mesh.faces) == 0:  # a replay session: no ground truth to show
            return
        self._put("/context/mesh", scene.add_mesh_simple(
            "/context/mesh", np.asarray(mesh.vertices, dtype=np.float32), np.asarray(mesh.faces, dtype=np.uint32),
            color=COLORS["mesh"], opacity=0.6, cast_shadow=False, receive_shadow=False, visible=self._visible("mesh"),
        ))  # fmt: skip

    # ------------------------------------------------------------------ the override gizmo

    def _gizmo_pose(self, data: SceneData) -> Pose | None:
        if data.plan is None or data.plan_id is None:
            return None
        if data.custom is not None:
            return data.custom.pose
        index = data.selected if data.selected is not None else data.plan.best_index
        return None if index is None else data.plan.candidates[index].T_world_camera

    def _draw_gizmo(self, data: SceneData) -> None:
        self._drop("/override")
        pose = self._gizmo_pose(data)
        if pose is None or not self.layers["gizmo"]:
            return
        gizmo = self.server.scene.add_transform_controls(
            "/override/gizmo", scale=0.08, wxyz=pose.wxyz, position=pose.translation, depth_test=False
        )
        gizmo.on_update(self._on_gizmo)
        self._put("/override/gizmo", gizmo)
        self._draw_gizmo_frustum(data)

    def _draw_gizmo_frustum(self, data: SceneData) -> None:
        if "/override/gizmo" not in self._handles:
            return
        ok = data.custom is None or data.custom.reachable
        self._drop("/override/gizmo/frustum")
        self._put("/override/gizmo/frustum", self.server.scene.add_camera_frustum(
            "/override/gizmo/frustum", fov=data.fov_y, aspect=data.aspect, scale=0.06, thickness=0.003,
            color=COLORS["custom_ok" if ok else "custom_bad"], cast_shadow=False, receive_shadow=False,
        ))  # fmt: skip

    def _on_gizmo(self, event: viser.TransformControlsEvent) -> None:
        if event.phase != "end":
            return
        wb = self._session
        if wb is None:
            return
        try:
            wb.set_custom(Pose.from_wxyz(np.asarray(event.target.wxyz), np.asarray(event.target.position)))
        except (WorkbenchError, ValueError) as exc:
            log.info("gizmo pose ignored: %s", exc)
