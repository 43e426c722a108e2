"""Debugging a fit in one viewer: its Fit panel rows, one ellipsoid at a time (focus), a kind's fit at another T.

The state (the refits shown, the focus) belongs to the viewer's clusters layer (app/scene/clusters.py), so two
tabs on one session inspect independently, and a new plan brings each back to the plan's fit. A refit runs in
the session's worker (``Session.refit``), outside the scene lock; it changes nothing of the session.

Every change of a viewer (its layers, its focus, a refit) is pushed to the page through the controller's
``viewer_listeners`` (app/api/events.py sends them on the tab's event socket): the page's layer bar and Fit
panel show the viewer's real state, whoever changed it.
"""

from __future__ import annotations

import logging
from contextlib import AbstractContextManager
from typing import Any, Protocol

from app.scene.clusters import PALETTES, ClustersLayer, cluster_colors
from app.scene.drawing import SessionDrawing
from planner.fit_quality import LOW_FILL, fit_rows, worst_filled_first
from workbench import Conflict, Invalid, SessionRegistry, WorkbenchError

log = logging.getLogger(__name__)


class Viewer(Protocol):
    """What this module reads of a viewer (app/scene/controller.py ``Viewer``)."""

    id: str
    session_id: str
    layers: dict[str, bool]
    drawing: SessionDrawing | None
    step: Any
    """The timeline's step it shows (``TimelineStep``), None: now."""


class Viewers(Protocol):
    """What this module asks of the SceneController."""

    registry: SessionRegistry

    @property
    def lock(self) -> AbstractContextManager[Any]: ...

    def viewer(self, viewer_id: str) -> Any: ...

    def set_layers(self, viewer_id: str, changes: dict[str, bool]) -> dict[str, bool]: ...

    def notify(self, v: Any) -> None: ...


def viewer_message(v: Viewer) -> dict[str, Any]:
    """``{"type": "viewer", "viewer", "layers", "focus", "refits": {kind: T}, "view": j | None}``: what the page is
    pushed (``view``: the timeline's view the viewer shows, None: now)."""
    layer = None if v.drawing is None else v.drawing.clusters
    return {
        "type": "viewer",
        "viewer": v.id,
        "layers": dict(v.layers),
        "focus": None if layer is None else layer.focus,
        "refits": {} if layer is None else {k: r.t for k, r in layer.refits.items()},
        "view": None if v.step is None else v.step.view,
    }


class FitViews:
    """The fit-debugging actions of a SceneController's viewers."""

    def __init__(self, controller: Viewers) -> None:
        self.controller = controller

    def _layer(self, viewer_id: str) -> tuple[Viewer, ClustersLayer]:
        v = self.controller.viewer(viewer_id)
        if v.drawing is None:
            raise Conflict(f"viewer {viewer_id}: not connected yet (its 3D view has not opened)")
        return v, v.drawing.clusters

    def info(self, viewer_id: str) -> dict[str, Any]:
        """The Fit panel: per kind the T shown (the plan's or a refit's), and one row per ellipsoid, worst-filled
        first per kind (see ``FitOut`` in app/api/fit.py)."""
        v = self.controller.viewer(viewer_id)
        session = self.controller.registry.get(v.session_id)
        entry = session.plan_for()
        plan = entry.plan
        selected = session.scene_data().selected
        with self.controller.lock:
            layer = None if v.drawing is None else v.drawing.clusters
            if layer is None or layer.fits == {} or not layer.drawn_from(plan):
                layer = ClustersLayer.detached(plan)
            fits, focus = dict(layer.fits), layer.focus
            refits = dict(layer.refits)
        res = plan.voxels.resolution
        score = plan.scores[selected] if selected is not None and 0 <= selected < len(plan.scores) else None
        per = score is not None and len(score.weighted) == len(plan.ellipsoids)
        offset = {"occupied": 0, "frontier": len(plan.occupied_ellipsoids)}
        kinds, rows = [], []
        for kind, f in fits.items():
            plan_fit = next((x for x in plan.fits if x.kind == kind), None)
            r = refits.get(kind)
            colors = cluster_colors(f.slots, PALETTES[kind])
            kind_rows = fit_rows(f.ellipsoids, res)
            kinds.append({
                "kind": kind, "t_plan": 0 if plan_fit is None else plan_fit.t_chosen, "t_shown": f.t,
                "refit": f.refit, "ellipsoids": len(f.ellipsoids), "voxels": len(f.points),
                "bic": None if r is None else float(r.fit.bic[0][1]),
                "low_fill": sum(row.low_fill for row in kind_rows),
            })  # fmt: skip
            for row in worst_filled_first(kind_rows):
                weighted = None
                if per and not f.refit and score is not None:
                    weighted = float(score.weighted[offset[kind] + row.index])
                rows.append({
                    "kind": kind, "label": row.label, "index": row.index, "voxels": row.voxels, "volume": row.volume,
                    "voxel_volume": row.voxel_volume, "fill": row.fill, "weight": row.weight, "weighted": weighted,
                    "low_fill": row.low_fill, "color": list(colors[row.index]),
                })  # fmt: skip
        return {
            "viewer": v.id, "session": v.session_id, "plan_id": entry.plan_id, "selected": selected,
            "focus": focus, "low_fill_threshold": LOW_FILL, "kinds": kinds, "rows": rows,
        }  # fmt: skip

    def refit(self, viewer_id: str, kind: str, t: int | None) -> dict[str, Any]:
        """Show ``kind``'s voxels fitted at ``t`` components in this viewer (None: back to the plan's fit); the
        clusters layer is turned on. Conflict when the plan changed while the worker fitted."""
        v, layer = self._layer(viewer_id)
        if kind not in ("occupied", "frontier"):
            raise Invalid(f"kind: must be occupied or frontier, got {kind!r}")
        session = self.controller.registry.get(v.session_id)
        refit = None if t is None else session.refit(kind, t)
        with self.controller.lock:
            entry = session.plan_for()
            if refit is not None and (refit.plan_id != entry.plan_id or not layer.drawn_from(entry.plan)):
                raise Conflict(f"viewer {viewer_id}: the plan changed while the fit at T={t} ran; ask again")
            layer.set_refit(kind, refit)
            assert v.drawing is not None
            v.drawing.redraw_clusters()
        self.controller.set_layers(viewer_id, {"clusters": True})  # pushes the viewer's state to its page
        return self.info(viewer_id)

    def focus(self, viewer_id: str, label: str | None) -> dict[str, Any]:
        """Highlight one ellipsoid (``O3``, ``F0``) and its voxels in this viewer, dim the rest; None: none."""
        v, layer = self._layer(viewer_id)
        with self.controller.lock:
            if label is not None and label not in layer.labels():
                raise Invalid(f"label: no ellipsoid {label!r} in the fit shown (known: {', '.join(layer.labels())})")
            layer.focus = label
            assert v.drawing is not None
            v.drawing.redraw_clusters()
        self.controller.notify(v)
        return self.info(viewer_id)

    def clicked(self, viewer_id: str, label: str) -> None:
        """A click on an ellipsoid in the 3D view (viser's thread): focus it."""
        try:
            self.focus(viewer_id, label)
        except WorkbenchError as exc:
            log.info("click on ellipsoid %s ignored: %s", label, exc.detail)
