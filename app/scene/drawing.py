"""One session drawn into one browser's own viser scene (``client.scene``), re-sending only what changed.

Node names (stable, per client)::

    /map/occupied /map/frontier /map/unknown /map/empty      voxel centres (float16 point clouds)
    /ellipsoids/occupied/3, /ellipsoids/frontier/0          MVEEs (translucent)
    /gmm/frontier/0                                          2-sigma GMM covariances (debug)
    /candidates                                              one batched mesh, clickable
    /nbv, /selected                                          the planner's choice, the selection
    /tour/path, /tour/1/frustum, /tour/1/label               the tour planner's predicted tour (numbered, in order)
    /views/7/frustum, /views/7/label                         views taken (new views are added, never re-sent)
    /context/bbox /context/sectors /context/turntable /context/mesh
    /context/session                                         "session ID": which session this scene shows
    /cloud/0, /cloud/1, ...                                  the registered cloud, one chunk per new part
    /surface                                                 the reconstructed surface (simplified, one mesh)
    /override/gizmo (+ /override/gizmo/frustum)              custom-pose transform gizmo
    /clusters/...                                            voxels by GMM cluster, ellipsoids named (app/scene/clusters.py)
    /reach/points                                            the hemisphere coloured by reachability (app/scene/reachlayer.py)
    /path/frustums, /path/edges, /path/line                  the camera along the move to the selected view, before
                                                             it is approved (app/scene/pathlayer.py)

What is re-sent: the plan's layers when the plan changes, only the views and cloud points that are new after
a capture, the selection when it changes. Hidden heavy layers (``LAZY``: empty / unknown voxels, GMM
ellipsoids, the ground-truth mesh) are sent only when first shown. The surface is sent while its layer is shown,
again only when the session's surface changed (a new view, a discard).
"""

from __future__ import annotations

import logging
import math
from collections.abc import Callable
from typing import Any

import numpy as np
import trimesh
import viser
from numpy.typing import NDArray

from app.scene.clusters import ClustersLayer
from app.scene.geometry import (
    COLORS,
    GROUPS,
    LAYER_NODES,
    box_segments,
    candidate_colors,
    ellipsoid_instance,
    gmm_instance,
    sector_label_positions,
    sector_segments,
)
from app.scene.pathlayer import (
    FRUSTUM_OPACITY,
    FRUSTUM_SCALE,
    PATH_COLORS,
    PathPreview,
    frame_colors,
    frustum_edges,
    frustum_pyramid,
)
from app.scene.reachlayer import ReachMap
from planner import PlanResult, Pose
from workbench import SceneData
from workbench.surface import SurfaceMesh

log = logging.getLogger(__name__)

_MARKER = trimesh.creation.icosphere(subdivisions=1, radius=1.0)
LAZY = ("occupied", "frontier", "unknown", "empty", "gmm", "mesh", "clusters")
"""Layers drawn only while visible (drawn on first show, then kept)."""
CLOUD_CELL = 0.004
"""Metres: a registered-cloud point is new (appended) when no drawn point shares its cell of this size."""
MAP_POINT_SIZE = {"occupied": 0.9, "frontier": 0.9, "unknown": 0.35, "empty": 0.3}
"""Voxel marker size, as a fraction of the voxel edge."""

Select = Callable[[int], None]
SetCustom = Callable[[Pose], None]


class SessionDrawing:
    """Draws SceneData into one client's scene. Not thread-safe: the owner (SceneController) holds a lock.

    client: the viser client whose own scene this is; layers: its layer visibility (shared with the owner);
    select(index) / set_custom(pose): what a click on a candidate / a gizmo release asks of the session.
    """

    def __init__(self, client: viser.ClientHandle, layers: dict[str, bool], select: Select, set_custom: SetCustom):
        self.client = client
        self.scene = client.scene
        self.layers = layers
        self.score_range = (0.0, 1.0)
        self._select = select
        self._set_custom = set_custom
        self._handles: dict[str, viser.SceneNodeHandle] = {}
        self._data: SceneData | None = None
        self._plan: PlanResult | None = None
        self._drawn_lazy: set[str] = set()
        self._views = 0
        self._cloud_cells: set[tuple[int, int, int]] = set()
        self._cloud_chunks = 0
        self._selection_key: tuple[Any, ...] | None = None
        self._context = False
        self._surface: SurfaceMesh | None = None  # the surface drawn now
        self.reach_map: ReachMap | None = None
        """The reach map drawn under /reach (None: none drawn)."""
        self.path: PathPreview | None = None
        """The move drawn under /path (None: none drawn)."""
        self.surface_sends = 0
        """How many times the surface was sent (it is re-sent only when it changed)."""
        for name, layer in GROUPS.items():
            visible = True if layer is None else self.layers[layer]
            self._put(name, self.scene.add_frame(name, show_axes=False, visible=visible))
        self.on_focus: Callable[[str], None] = lambda label: None
        """What a click on an ellipsoid of the clusters layer asks (set by the owner)."""
        self.clusters = ClustersLayer(self.scene, self._put, self._drop, lambda label: self.on_focus(label))

    # ------------------------------------------------------------------ public

    def node_names(self) -> list[str]:
        return sorted(self._handles)

    def update(self, data: SceneData) -> None:
        """Bring the client's scene to ``data``, sending only the layers that changed."""
        with self.client.atomic():
            self._data = data
            if not self._context:
                self._context = True
                self._draw_turntable(data)
            if data.plan is not self._plan:
                self._draw_plan(data)
            if len(data.views) < self._views:  # a view was discarded: draw the views and the cloud again
                self._drop("/views")
                self._drop("/cloud")
                self._views = self._cloud_chunks = 0
                self._cloud_cells.clear()
            self._sync_views(data)
            self._sync_cloud(data)
            self._sync_selection(data)
            self._sync_surface(data)
            for layer in LAZY:
                if self.layers[layer] and layer not in self._drawn_lazy:
                    self._draw_lazy(layer, data)

    def clear(self) -> None:
        """Remove everything but the group nodes (the session is gone)."""
        with self.client.atomic():
            for name in [n for n in self._handles if n not in GROUPS]:
                self._drop(name)
            self._data = self._plan = None
            self.clusters.new_plan(None)
            self._drawn_lazy.clear()
            self._views = self._cloud_chunks = 0
            self._cloud_cells.clear()
            self._selection_key = None
            self._context = False
            self._surface = None
            self.reach_map = None
            self.path = None

    def set_layers(self, changes: dict[str, bool]) -> None:
        """Show / hide layers (names checked by the caller); a lazy layer shown for the first time is sent now."""
        with self.client.atomic():
            self.layers.update(changes)
            for layer, on in changes.items():
                for name in LAYER_NODES[layer]:
                    handle = self._handles.get(name)
                    if handle is not None:
                        handle.visible = on
                if on and layer in LAZY and layer not in self._drawn_lazy and self._data is not None:
                    self._draw_lazy(layer, self._data)
            if changes.get("surface") and self._data is not None:
                self._sync_surface(self._data)
            if "gizmo" in changes and self._data is not None:
                self._selection_key = None
                self._sync_selection(self._data)

    def redraw_clusters(self) -> None:
        """Send the clusters layer again (a focus or a refit changed it) if it is shown, else when next shown."""
        with self.client.atomic():
            if self.layers["clusters"]:
                self.clusters.draw()
                self._drawn_lazy.add("clusters")
            else:
                self._drawn_lazy.discard("clusters")

    def draw_reach(self, reach: ReachMap | None) -> None:
        """Draw ``reach`` under /reach/points (one point per view, its class's colour); None: remove it."""
        if reach is self.reach_map:
            return
        with self.client.atomic():
            self._drop("/reach")
            self.reach_map = reach
            if reach is None or len(reach.positions) == 0:
                return
            self._put("/reach/points", self.scene.add_point_cloud(
                "/reach/points", reach.positions, reach.colors, point_size=0.1 * reach.spacing,
                precision="float32", point_shape="circle", point_shading="flat",
            ))  # fmt: skip

    def draw_path(self, preview: PathPreview | None) -> None:
        """Draw the camera along ``preview``'s move under /path (frustums where the frames are taken, outlined, and
        the centre's line from the current pose to the view); None: remove it."""
        if preview is self.path:
            return
        with self.client.atomic():
            self._drop("/path")
            self.path = preview
            data = self._data
            if preview is None or data is None:
                return
            _, poses = preview.drawn()
            if poses:
                k = len(poses)
                vertices, faces = frustum_pyramid(data.fov_y, data.aspect)
                colors = frame_colors(k)
                self._put("/path/frustums", self.scene.add_batched_meshes_simple(
                    "/path/frustums", vertices, faces,
                    batched_wxyzs=np.array([p.wxyz for p in poses], dtype=np.float32),
                    batched_positions=np.array([p.translation for p in poses], dtype=np.float32),
                    batched_scales=np.full(k, FRUSTUM_SCALE, dtype=np.float32), batched_colors=colors,
                    opacity=FRUSTUM_OPACITY, lod="off", side="double", cast_shadow=False, receive_shadow=False,
                ))  # fmt: skip
                edges = frustum_edges(poses, data.fov_y, data.aspect, FRUSTUM_SCALE)
                edge_colors = np.repeat(colors, 8 * 2, axis=0).reshape(-1, 2, 3)
                self._put("/path/edges", self.scene.add_line_segments(
                    "/path/edges", edges, edge_colors, thickness=2.0, thickness_units="screen",
                ))  # fmt: skip
            points = np.array([p.translation for p in preview.line], dtype=np.float32)
            segments = np.stack([points[:-1], points[1:]], axis=1)
            self._put("/path/line", self.scene.add_line_segments(
                "/path/line", segments, PATH_COLORS[0], thickness=3.5, thickness_units="screen",
            ))  # fmt: skip

    def candidate_at(self, event: viser.SceneNodePointerEvent) -> int | None:
        """The candidate index a click on /candidates hit (the instance, else the marker nearest the ray)."""
        data = self._data
        if data is None or data.plan is None or not data.plan.candidates:
            return None
        if event.instance_index is not None:
            return int(event.instance_index)
        o, d = np.asarray(event.ray_origin), np.asarray(event.ray_direction)
        p = np.stack([c.position for c in data.plan.candidates]) - o
        return int(np.argmin(np.linalg.norm(p - np.outer(p @ d, d), axis=1)))

    # ------------------------------------------------------------------ helpers

    def _put(self, name: str, handle: viser.SceneNodeHandle) -> None:
        self._handles[name] = handle

    def _drop(self, prefix: str) -> None:
        """Remove the node ``prefix`` (if it is not a group) and every node below it."""
        for name in [n for n in self._handles if n.startswith(prefix + "/") or (n == prefix and n not in GROUPS)]:
            handle = self._handles.pop(name)
            if not handle._impl.removed:
                handle.remove()

    # ------------------------------------------------------------------ the plan's layers

    def _draw_plan(self, data: SceneData) -> None:
        self._plan = data.plan
        for name in (
            "/map", "/ellipsoids", "/gmm", "/candidates", "/context/bbox", "/context/sectors", "/clusters", "/tour"
        ):  # fmt: skip
            self._drop(name)
        self._drawn_lazy -= {"occupied", "frontier", "unknown", "empty", "gmm", "clusters"}
        self._selection_key = None
        plan = data.plan
        self.clusters.new_plan(plan)
        if plan is None:
            return
        counts = {"occupied": 0, "frontier": 0}
        for e in plan.ellipsoids:
            i = counts[e.kind]
            counts[e.kind] += 1
            wxyz, pos, axes = ellipsoid_instance(e)
            name = f"/ellipsoids/{e.kind}/{i}"
            self._put(name, self.scene.add_icosphere(
                name, 1.0, COLORS[f"ellipsoid_{e.kind}"], subdivisions=2, scale=tuple(axes), opacity=0.3,
                wxyz=wxyz, position=pos, cast_shadow=False, receive_shadow=False, side="double",
            ))  # fmt: skip
        self._draw_candidates(plan)
        self._draw_tour(data)
        self._put("/context/bbox", self.scene.add_line_segments(
            "/context/bbox", box_segments(plan.bbox), COLORS["bbox"], thickness=1.5, thickness_units="screen",
            visible=self.layers["bbox"],
        ))  # fmt: skip
        radius = plan.hemisphere_radius
        segs = sector_segments(plan.hemisphere_center, radius, plan.sector_edges)
        self._put("/context/sectors/lines", self.scene.add_line_segments(
            "/context/sectors/lines", segs, COLORS["sector"], thickness=2.0, thickness_units="screen",
        ))  # fmt: skip
        labels = sector_label_positions(plan.hemisphere_center, 0.9 * radius, plan.sector_edges)
        for k, pos in enumerate(labels):
            tag = "scanned" if k in plan.scanned_sectors else ("eligible" if k in plan.eligible_sectors else "locked")
            name = f"/context/sectors/{k}"
            self._put(name, self.scene.add_label(name, f"S{k} {tag}", position=pos, font_screen_scale=0.7))

    def _draw_tour(self, data: SceneData) -> None:
        """The ``tour`` planner's predicted tour: a frustum per view numbered in visit order (with the predicted
        move seconds until it), and the path from the last view taken through them."""
        plan = data.plan
        tour = None if plan is None else plan.tour
        if plan is None or tour is None or not tour.views:
            return
        poses = [plan.candidates[i].T_world_camera for i in tour.views]
        points = [p.translation for p in poses]
        if data.views:
            points.insert(0, data.views[-1].translation)
        if len(points) > 1:
            segments = np.stack([np.array(points[:-1]), np.array(points[1:])], axis=1)
            self._put("/tour/path", self.scene.add_line_segments(
                "/tour/path", segments, COLORS["tour"], thickness=2.5, thickness_units="screen",
            ))  # fmt: skip
        for k, (pose, seconds) in enumerate(zip(poses, tour.seconds, strict=True), start=1):
            self._put(f"/tour/{k}/frustum", self.scene.add_camera_frustum(
                f"/tour/{k}/frustum", fov=data.fov_y, aspect=data.aspect, color=COLORS["tour"], wxyz=pose.wxyz,
                position=pose.translation, scale=0.05, thickness=0.003, cast_shadow=False, receive_shadow=False,
            ))  # fmt: skip
            self._put(f"/tour/{k}/label", self.scene.add_label(
                f"/tour/{k}/label", f"{k} · {seconds:.1f} s", position=pose.translation, font_screen_scale=0.7,
            ))  # fmt: skip

    def _draw_lazy(self, layer: str, data: SceneData) -> None:
        self._drawn_lazy.add(layer)
        if layer == "mesh":
            self._draw_mesh(data)
            return
        if layer == "clusters":
            self.clusters.draw()
            return
        plan = data.plan
        if plan is None:
            return
        if layer == "gmm":
            counts = {"occupied": 0, "frontier": 0}
            for e in plan.ellipsoids:
                i = counts[e.kind]
                counts[e.kind] += 1
                gmm = gmm_instance(e)
                if gmm is not None:
                    name = f"/gmm/{e.kind}/{i}"
                    self._put(name, self.scene.add_icosphere(
                        name, 1.0, COLORS[f"gmm_{e.kind}"], subdivisions=1, scale=tuple(gmm[2]), wireframe=True,
                        wxyz=gmm[0], position=gmm[1], cast_shadow=False, receive_shadow=False,
                    ))  # fmt: skip
            return
        vox = plan.voxels
        pts = np.asarray(getattr(vox, layer), dtype=np.float16).reshape(-1, 3)
        name = f"/map/{layer}"
        self._put(name, self.scene.add_point_cloud(
            name, pts, COLORS[layer], point_size=MAP_POINT_SIZE[layer] * vox.resolution, precision="float16",
            point_shape="square", point_shading="flat", visible=self.layers[layer],
        ))  # fmt: skip

    def _draw_candidates(self, plan: PlanResult) -> None:
        n = len(plan.candidates)
        if n == 0:
            return
        colors, lo, hi = candidate_colors([s.score for s in plan.scores], [s.eligible for s in plan.scores])
        self.score_range = (lo, hi)
        spacing = math.sqrt(2.0 * math.pi * plan.hemisphere_radius**2 / n)
        positions = np.stack([c.position for c in plan.candidates]).astype(np.float32)
        handle = self.scene.add_batched_meshes_simple(
            "/candidates", _MARKER.vertices, _MARKER.faces,
            batched_wxyzs=np.tile(np.array([1.0, 0.0, 0.0, 0.0], dtype=np.float32), (n, 1)),
            batched_positions=positions, batched_scales=np.full(n, 0.16 * spacing, dtype=np.float32),
            batched_colors=colors, lod="off", cast_shadow=False, receive_shadow=False,
            visible=self.layers["candidates"],
        )  # fmt: skip
        handle.on_click(self._on_candidate_click)
        self._put("/candidates", handle)

    def _on_candidate_click(self, event: viser.SceneNodePointerEvent) -> None:
        index = self.candidate_at(event)
        if index is not None:
            self._select(index)

    # ------------------------------------------------------------------ views, cloud, context

    def _sync_views(self, data: SceneData) -> None:
        for i in range(self._views + 1, len(data.views) + 1):
            pose = data.views[i - 1]
            root = f"/views/{i}"
            self._put(root, self.scene.add_frame(root, show_axes=False, wxyz=pose.wxyz, position=pose.translation))
            self._put(f"{root}/frustum", self.scene.add_camera_frustum(
                f"{root}/frustum", fov=data.fov_y, aspect=data.aspect, scale=0.045, thickness=0.002,
                color=COLORS["view"], cast_shadow=False, receive_shadow=False,
            ))  # fmt: skip
            self._put(f"{root}/label", self.scene.add_label(f"{root}/label", str(i), font_screen_scale=0.8))
        self._views = len(data.views)

    def _sync_cloud(self, data: SceneData) -> None:
        pts = np.asarray(data.cloud, dtype=np.float64).reshape(-1, 3)
        new = new_cloud_points(pts, self._cloud_cells)
        if len(new) == 0:
            return
        name = f"/cloud/{self._cloud_chunks}"
        self._cloud_chunks += 1
        # shown: the /cloud group hides and shows every chunk (a chunk's own flag would stay as it was drawn)
        self._put(name, self.scene.add_point_cloud(
            name, new.astype(np.float16), COLORS["cloud"], point_size=0.002, precision="float16",
            point_shading="flat",
        ))  # fmt: skip

    def _draw_turntable(self, data: SceneData) -> None:
        r = data.plate_radius
        self._put("/context/session", self.scene.add_label(
            "/context/session", f"session {data.session_id}", position=(0.0, -1.1 * r, 0.0), font_screen_scale=0.6,
        ))  # fmt: skip
        self._put("/context/turntable", self.scene.add_cylinder(
            "/context/turntable", radius=data.plate_radius, height=0.01, color=COLORS["plate"], radial_segments=48,
            position=(0.0, 0.0, -0.0051), cast_shadow=False, receive_shadow=False, visible=self.layers["turntable"],
        ))  # fmt: skip

    def _sync_surface(self, data: SceneData) -> None:
        """Send the surface when its layer is shown and it is not the one drawn (drop it when there is none)."""
        if data.surface is self._surface or not self.layers["surface"]:
            return
        self._drop("/surface")
        self._surface = data.surface
        if data.surface is None:
            return
        self.surface_sends += 1
        self._put("/surface", self.scene.add_mesh_simple(
            "/surface", data.surface.vertices.astype(np.float32), data.surface.faces.astype(np.uint32),
            color=COLORS["surface"], flat_shading=False, side="double", cast_shadow=False, receive_shadow=False,
        ))  # fmt: skip

    def _draw_mesh(self, data: SceneData) -> None:
        mesh = data.mesh
        if len(mesh.faces) == 0:  # a replay session: no ground truth to show
            return
        self._put("/context/mesh", self.scene.add_mesh_simple(
            "/context/mesh", np.asarray(mesh.vertices, dtype=np.float32), np.asarray(mesh.faces, dtype=np.uint32),
            color=COLORS["mesh"], opacity=0.6, cast_shadow=False, receive_shadow=False, visible=self.layers["mesh"],
        ))  # fmt: skip

    # ------------------------------------------------------------------ selection and the override gizmo

    def _sync_selection(self, data: SceneData) -> None:
        custom = None if data.custom is None else (tuple(data.custom.pose.to_dict()["position"]), data.custom.reachable)
        key = (id(data.plan), data.plan_id, data.selected, custom, self.layers["gizmo"], self.layers["nbv"])
        if key == self._selection_key:
            return
        self._selection_key = key
        self._drop("/nbv")
        self._drop("/selected")
        self._drop("/override")
        plan = data.plan
        if plan is None or data.plan_id is None:
            return
        visible = self.layers["nbv"]
        if plan.best is not None:
            self._frustum("/nbv", plan.best.T_world_camera, data, COLORS["nbv"], visible=visible)
        if data.selected is not None and data.selected != plan.best_index:
            self._frustum("/selected", plan.candidates[data.selected].T_world_camera, data, COLORS["selected"],
                          visible=visible)  # fmt: skip
        self._draw_gizmo(data)

    def _frustum(self, name: str, pose: Pose, data: SceneData, color: tuple[int, int, int], visible: bool) -> None:
        self._put(name, self.scene.add_camera_frustum(
            name, fov=data.fov_y, aspect=data.aspect, color=color, wxyz=pose.wxyz, position=pose.translation,
            scale=0.07, thickness=0.004, visible=visible, variant="filled", cast_shadow=False, receive_shadow=False,
        ))  # fmt: skip

    def _draw_gizmo(self, data: SceneData) -> None:
        if not self.layers["gizmo"] or data.plan is None:
            return
        if data.custom is not None:
            pose = data.custom.pose
        else:
            index = data.selected if data.selected is not None else data.plan.best_index
            if index is None:
                return
            pose = data.plan.candidates[index].T_world_camera
        gizmo = self.scene.add_transform_controls(
            "/override/gizmo", scale=0.08, wxyz=pose.wxyz, position=pose.translation, depth_test=False
        )
        gizmo.on_update(self._on_gizmo)
        self._put("/override/gizmo", gizmo)
        ok = data.custom is None or data.custom.reachable
        self._put("/override/gizmo/frustum", self.scene.add_camera_frustum(
            "/override/gizmo/frustum", fov=data.fov_y, aspect=data.aspect, scale=0.06, thickness=0.003,
            color=COLORS["custom_ok" if ok else "custom_bad"], cast_shadow=False, receive_shadow=False,
        ))  # fmt: skip

    def _on_gizmo(self, event: viser.TransformControlsEvent) -> None:
        if event.phase != "end":
            return
        self._set_custom(Pose.from_wxyz(np.asarray(event.target.wxyz), np.asarray(event.target.position)))


def new_cloud_points(points: NDArray[np.float64], cells: set[tuple[int, int, int]]) -> NDArray[np.float64]:
    """The rows of ``points`` (N, 3) whose CLOUD_CELL cell is not in ``cells`` (one per cell); ``cells`` grows.

    Returns (M, 3) float64, M <= N.
    """
    if len(points) == 0:
        return points.reshape(0, 3)
    keys = np.floor(points / CLOUD_CELL).astype(np.int64)
    _, first = np.unique(keys, axis=0, return_index=True)
    out = []
    for i in np.sort(first):
        key = (int(keys[i, 0]), int(keys[i, 1]), int(keys[i, 2]))
        if key not in cells:
            cells.add(key)
            out.append(i)
    return points[out].reshape(-1, 3)
