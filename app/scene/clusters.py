"""The clusters layer: each occupied and frontier voxel in the colour of its GMM component, each ellipsoid in its
cluster's colour and labelled (O3, F0: the inspector's names), one ellipsoid at a time, a kind's fit at another T.

Colours. Each kind has its own palette (occupied cool, frontier warm). A cluster keeps its palette slot from
the fit drawn before when it is still there: a new ellipsoid takes the slot of the nearest earlier one whose
centre is within the larger of the two major semi-axes (closest pairs first, one to one); the others take the
lowest free slots (the palette repeats beyond its length).

Nodes (under the ``/clusters`` group, the ``clusters`` layer)::

    /clusters/occupied/voxels, /clusters/frontier/voxels    voxel centres, one colour per voxel
    /clusters/occupied/3, /clusters/frontier/0               the ellipsoids (clickable: focus)
    /clusters/labels/O3, /clusters/labels/F0                 their names, at each ellipsoid's top

Focus (one ellipsoid): its voxels and ellipsoid keep their colours, every other cluster is dimmed towards
light grey.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import dataclass, field

import numpy as np
import viser
from numpy.typing import NDArray

from app.scene.geometry import ellipsoid_instance
from planner import Ellipsoid, PlanResult
from planner.fit_quality import ellipsoid_label
from workbench import Refit

PALETTES: dict[str, tuple[tuple[int, int, int], ...]] = {
    "occupied": (
        (31, 119, 180), (44, 160, 44), (148, 103, 189), (23, 190, 207), (57, 59, 121), (0, 109, 44),
        (107, 174, 214), (116, 196, 118), (82, 84, 163), (99, 121, 57), (156, 158, 222), (8, 69, 148),
    ),
    "frontier": (
        (214, 39, 40), (255, 127, 14), (227, 119, 194), (188, 189, 34), (140, 86, 75), (253, 174, 97),
        (165, 0, 38), (231, 41, 138), (254, 196, 79), (204, 76, 2), (250, 159, 181), (128, 64, 0),
    ),
}  # fmt: skip
"""Per kind, the cluster colours (RGB), slot 0 first."""
DIM_TOWARDS = np.array([232.0, 232.0, 236.0])
DIM = 0.82
"""With a focus, other clusters' colours move this fraction of the way to DIM_TOWARDS."""
OPACITY = {"normal": 0.3, "focus": 0.55, "dimmed": 0.06}
"""Ellipsoid opacity: without a focus, the focused one, the others."""


def carry_slots(
    prev_centers: NDArray[np.float64],
    prev_radii: NDArray[np.float64],
    prev_slots: Sequence[int],
    centers: NDArray[np.float64],
    radii: NDArray[np.float64],
) -> list[int]:
    """Palette slots of new clusters (centres (N, 3), major semi-axes (N,)) given the earlier ones' (M, 3), (M,),
    slots (M,): the module docstring's rule. Returns N slot numbers (>= 0, unbounded; take them modulo a
    palette's length)."""
    n = len(centers)
    out: list[int | None] = [None] * n
    if len(prev_centers) and n:
        d = np.linalg.norm(centers[:, None, :] - prev_centers[None, :, :], axis=2)  # (N, M)
        reach = np.maximum(radii[:, None], prev_radii[None, :])
        taken: set[int] = set()
        used_prev: set[int] = set()
        for flat in np.argsort(d, axis=None, kind="stable"):
            i, j = divmod(int(flat), len(prev_centers))
            if d[i, j] >= reach[i, j]:
                break
            if out[i] is None and j not in used_prev and prev_slots[j] not in taken:
                out[i] = int(prev_slots[j])
                used_prev.add(j)
                taken.add(int(prev_slots[j]))
    kept = {x for x in out if x is not None}
    result, slot = [], 0
    for x in out:
        if x is None:
            while slot in kept:
                slot += 1
            x = slot
            slot += 1
        result.append(x)
    return result


def voxel_colors(
    labels: NDArray[np.integer], slots: Sequence[int], palette: Sequence[tuple[int, int, int]], focus: int | None
) -> NDArray[np.uint8]:
    """(N, 3) uint8 colour of each voxel: ``palette[slots[labels[k]] % len]``; with ``focus`` (a cluster index,
    or -1: none of this kind) the other clusters' voxels dimmed (:data:`DIM`)."""
    colors = np.asarray(cluster_colors(slots, palette, focus), dtype=np.uint8).reshape(-1, 3)
    return colors[np.asarray(labels, dtype=np.int64)]


def cluster_colors(
    slots: Sequence[int], palette: Sequence[tuple[int, int, int]], focus: int | None = None
) -> list[tuple[int, int, int]]:
    """The colour of each cluster (slot modulo the palette), the non-focused ones dimmed when there is a focus."""
    out = []
    for k, s in enumerate(slots):
        c = np.asarray(palette[s % len(palette)], dtype=np.float64)
        if focus is not None and k != focus:
            c = c + DIM * (DIM_TOWARDS - c)
        out.append(tuple(int(v) for v in np.round(c)))
    return out


@dataclass
class KindFit:
    """What the layer shows for one kind: its ellipsoids, each voxel's cluster, the T, whether it is a refit."""

    kind: str
    ellipsoids: tuple[Ellipsoid, ...]
    points: NDArray[np.float64]
    labels: NDArray[np.int32] | None
    t: int
    refit: bool
    slots: list[int] = field(default_factory=list)


def plan_fits(plan: PlanResult, refits: dict[str, Refit]) -> dict[str, KindFit]:
    """Per kind, the plan's fit or the refit asked for it."""
    out = {}
    for kind in ("occupied", "frontier"):
        points = plan.voxels.occupied if kind == "occupied" else plan.voxels.frontier
        r = refits.get(kind)
        if r is not None:
            out[kind] = KindFit(kind, r.ellipsoids, points, r.fit.labels, r.t, True)
            continue
        fit = next((f for f in plan.fits if f.kind == kind), None)
        mine = tuple(e for e in plan.ellipsoids if e.kind == kind)
        out[kind] = KindFit(kind, mine, points, None if fit is None else fit.labels, len(mine), False)
    return out


class ClustersLayer:
    """The clusters layer of one viewer's scene (drawn by its SessionDrawing, which holds the lock).

    put / drop: the drawing's node bookkeeping; on_focus(label): a click on an ellipsoid.
    """

    def __init__(
        self,
        scene: viser.SceneApi,
        put: Callable[[str, viser.SceneNodeHandle], None],
        drop: Callable[[str], None],
        on_focus: Callable[[str], None],
    ) -> None:
        self.scene = scene
        self._put, self._drop, self._on_focus = put, drop, on_focus
        self.refits: dict[str, Refit] = {}
        self.focus: str | None = None
        self.fits: dict[str, KindFit] = {}
        self._plan: PlanResult | None = None
        self._last: dict[str, tuple[NDArray[np.float64], NDArray[np.float64], list[int]]] = {}

    @classmethod
    def detached(cls, plan: PlanResult) -> ClustersLayer:
        """A layer of ``plan`` drawn nowhere (what a viewer would show before it connects)."""
        layer = cls(None, lambda name, handle: None, lambda name: None, lambda label: None)  # type: ignore[arg-type]
        layer.new_plan(plan)
        return layer

    def drawn_from(self, plan: PlanResult) -> bool:
        """Whether this layer shows ``plan`` (the scene may lag a new plan by a moment)."""
        return self._plan is plan

    def new_plan(self, plan: PlanResult | None) -> None:
        """A new plan: back to its fit, no focus (the colours carry over where clusters stay)."""
        self.refits.clear()
        self.focus = None
        self._plan = plan
        self._refresh()

    def set_refit(self, kind: str, refit: Refit | None) -> None:
        if refit is None:
            self.refits.pop(kind, None)
        else:
            self.refits[kind] = refit
        if self.focus is not None and self.focus[0] == kind[0].upper():
            self.focus = None
        self._refresh()

    def _refresh(self) -> None:
        """Recompute what is shown per kind and its palette slots (carried over from what was shown before)."""
        if self._plan is None:
            self.fits = {}
            return
        self.fits = plan_fits(self._plan, self.refits)
        for kind, f in self.fits.items():
            centers = np.array([e.center for e in f.ellipsoids]).reshape(-1, 3)
            radii = np.array([e.axes.max() for e in f.ellipsoids])
            prev = self._last.get(kind, (np.zeros((0, 3)), np.zeros(0), []))
            f.slots = carry_slots(prev[0], prev[1], prev[2], centers, radii)
            self._last[kind] = (centers, radii, f.slots)

    def focus_index(self) -> tuple[str, int] | None:
        """(kind, index) of the focused ellipsoid, None without a focus."""
        if self.focus is None:
            return None
        kind = "occupied" if self.focus[0] == "O" else "frontier"
        return kind, int(self.focus[1:])

    def labels(self) -> list[str]:
        return [ellipsoid_label(k, i) for k, f in self.fits.items() for i in range(len(f.ellipsoids))]  # type: ignore[arg-type]

    def draw(self) -> None:
        """Send the layer (everything under /clusters) as it is now."""
        self._drop("/clusters")
        plan = self._plan
        if plan is None:
            return
        focus = self.focus_index()
        for kind, f in self.fits.items():
            palette = PALETTES[kind]
            fi = focus[1] if focus is not None and focus[0] == kind else None
            dim_all = focus is not None and focus[0] != kind
            keep = -1 if dim_all else fi
            colors = cluster_colors(f.slots, palette, keep)
            if f.labels is not None and len(f.labels) == len(f.points) and len(f.points):
                name = f"/clusters/{kind}/voxels"
                self._put(name, self.scene.add_point_cloud(
                    name, f.points.astype(np.float16), voxel_colors(f.labels, f.slots, palette, keep),
                    point_size=0.9 * plan.voxels.resolution, precision="float16", point_shape="square",
                    point_shading="flat",
                ))  # fmt: skip
            for i, e in enumerate(f.ellipsoids):
                label = ellipsoid_label(kind, i)  # type: ignore[arg-type]
                state = "normal" if focus is None else ("focus" if fi == i else "dimmed")
                wxyz, pos, axes = ellipsoid_instance(e)
                name = f"/clusters/{kind}/{i}"
                handle = self.scene.add_icosphere(
                    name, 1.0, colors[i], subdivisions=2, scale=tuple(axes), opacity=OPACITY[state], wxyz=wxyz,
                    position=pos, cast_shadow=False, receive_shadow=False, side="double",
                )  # fmt: skip
                handle.on_click(lambda _event, label=label: self._on_focus(label))
                self._put(name, handle)
                if state != "dimmed":
                    top = e.center + np.array([0.0, 0.0, _extent_z(e)])
                    lname = f"/clusters/labels/{label}"
                    self._put(lname, self.scene.add_label(
                        lname, label, position=top, font_screen_scale=0.6, anchor="bottom-center",
                    ))  # fmt: skip


def _extent_z(e: Ellipsoid) -> float:
    """Half the ellipsoid's height: sqrt(sum_k (R[2, k] a_k)^2)."""
    return float(np.sqrt(np.sum((e.rotation[2] * e.axes) ** 2)))
