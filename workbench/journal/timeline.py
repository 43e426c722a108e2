"""A session's timeline: the session as it was after each of its views, rebuilt from its journal.

Step ``j`` (1-based) is what a person saw after view ``j`` was integrated: the views taken so far, the registered
cloud, the voxel counts and coverage of that capture, the plan made from it (the one a decision answered when
several were made; its ellipsoids, candidates, scores and best view) and the decision taken on that plan (the
approved candidate, an override, a custom pose; None while the plan still waits). The steps come from one
:func:`workbench.journal.rebuild.rebuild` of the journal (``keep_scene``), so they are exactly what the live
session computed (the rebuild checks every plan's best view against the journal). Nothing of a live session is
read or changed: a timeline is built from the journal on disk alone (workbench/session/history.py caches it).
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, replace
from pathlib import Path
from typing import Any

import numpy as np
import trimesh
from numpy.typing import NDArray

from devices.config import DeviceConfig
from planner import PlanResult, Pose
from planner.config import from_dict
from workbench.journal.discard import without_discarded
from workbench.journal.rebuild import Rebuilt, rebuild, replay_cell
from workbench.journal.store import Journal, read_journal
from workbench.session.summaries import best_of, plan_fields
from workbench.session.values import CustomPose, SceneData


@dataclass(frozen=True, eq=False)
class TimelineStep:
    """The session after view ``view``: what its scene drew and its panels showed then.

    views: the poses of views 1..view; cloud: (N, 3) float64 registered points after it; plan: the plan made from
    it (None when none was); decision: the journal's ``decision`` event that answered that plan (None: none yet);
    drawn: the plan the scene draws (``plan``, else the last one made before, as a live session shows it).
    """

    view: int
    views: tuple[Pose, ...]
    cloud: NDArray[np.float64]
    voxels: dict[str, int]
    points: int
    coverage: float | None
    plan: PlanResult | None
    plan_id: str | None
    decision: dict[str, Any] | None
    device_state: dict[str, Any] | None
    drawn: PlanResult | None = None
    move_frames: int = 0
    """Capture during moves: the frames kept from the move to this view (they belong to it)."""

    @property
    def approved(self) -> int | None:
        """The candidate the decision on this step's plan took (None: none, or a custom pose)."""
        d = self.decision
        return None if d is None or d.get("custom") else d.get("index")

    def custom(self) -> CustomPose | None:
        """The custom pose the decision took, when it was one."""
        d = self.decision
        if d is None or not d.get("custom") or d.get("pose") is None:
            return None
        return CustomPose(Pose.from_dict(d["pose"]), True, "the custom pose approved at this view")

    def scene_data(self, now: SceneData) -> SceneData:
        """``now`` (the session's scene today: its mesh, plate, camera) as it was at this step (no surface)."""
        selected = self.approved if self.approved is not None else (None if self.plan is None else self.plan.best_index)
        return replace(
            now,
            plan=self.plan if self.plan is not None else self.drawn,
            plan_id=self.plan_id,
            views=self.views,
            cloud=self.cloud,
            selected=selected,
            custom=self.custom(),
            surface=None,
        )

    def summary(self) -> dict[str, Any]:
        """The step as the page shows it: ``{"view", "plan_id", "best", "approved", "decision", "voxels",
        "points", "coverage", "move_frames", "n_candidates", "n_eligible", "terminated"}`` (plan fields None without a
        plan)."""
        d = self.decision
        fields = plan_fields(self.plan) if self.plan is not None else {}
        return {
            "view": self.view,
            "plan_id": self.plan_id,
            "best": None if self.plan is None else best_of(self.plan),
            "approved": self.approved,
            "decision": None
            if d is None
            else {
                "kind": d.get("decision"),
                **{k: d.get(k) for k in ("plan_id", "index", "best_index", "custom", "pose")},
            },
            "voxels": dict(self.voxels),
            "points": self.points,
            "coverage": self.coverage,
            "move_frames": self.move_frames,
            "n_candidates": fields.get("n_candidates"),
            "n_eligible": fields.get("n_eligible"),
            "terminated": fields.get("terminated"),
        }


def steps_of(journal: Journal, rebuilt: Rebuilt) -> list[TimelineStep]:
    """The steps of a rebuild made with ``keep_scene`` (one per replayed capture, in order)."""
    decisions: dict[str, dict[str, Any]] = {}  # plan id -> the decision whose view was taken (and kept)
    taken: dict[str, Any] | None = None
    for ev in without_discarded(journal.events):
        if ev.get("kind") == "decision":
            taken = ev  # a decision retried after a fault, or one whose view was discarded: the last one counts
        elif ev.get("kind") == "capture":
            if taken is not None and taken.get("plan_id") is not None:
                decisions[str(taken["plan_id"])] = taken
            taken = None
    steps: list[TimelineStep] = []
    for k, capture in enumerate(rebuilt.captures, start=1):
        if capture.views is None or capture.cloud is None:
            raise ValueError("steps_of: the rebuild did not keep the scene (rebuild(..., keep_scene=True))")
        chosen = next(((ev, p) for ev, p in capture.plans if str(ev["plan_id"]) in decisions), None)
        plan_ev, plan = chosen or (capture.plans[-1] if capture.plans else (None, None))
        plan_id = None if plan_ev is None else str(plan_ev["plan_id"])
        ev = capture.event
        steps.append(
            TimelineStep(
                view=k,
                views=capture.views,
                cloud=capture.cloud,
                voxels=dict(capture.voxels),
                points=int(ev.get("points", capture.report.n_points_total)),
                coverage=ev.get("coverage", capture.coverage),
                plan=plan,
                plan_id=plan_id,
                decision=None if plan_id is None else decisions.get(plan_id),
                device_state=ev.get("device_state"),
                drawn=plan if plan is not None else (steps[-1].drawn if steps else None),
                move_frames=len(ev.get("move_frames") or []),
            )
        )
    return steps


def timeline_of(
    journal: Journal,
    cell: Any,
    coverage: Callable[[NDArray[np.float64]], float] | None = None,
    progress: Callable[[str, int, int], None] | None = None,
) -> list[TimelineStep]:
    """Every step of ``journal``'s session (one per kept view), replayed in ``cell`` (as
    :func:`workbench.journal.rebuild.rebuild` asks it). ValueError for a journal that cannot be replayed."""
    rebuilt = rebuild(journal, cell, coverage, progress, keep_scene=True)
    return steps_of(journal, rebuilt)


def journal_scene(journal: Journal) -> SceneData:
    """The scene of the journaled session with nothing drawn yet: its plate and camera model, no mesh (what a
    :meth:`TimelineStep.scene_data` fills in)."""
    devices = from_dict(DeviceConfig, journal.header["devices"])
    k = devices.camera.intrinsics
    return SceneData(
        session_id=journal.session_id,
        plan=None,
        plan_id=None,
        views=(),
        cloud=np.zeros((0, 3)),
        selected=None,
        custom=None,
        mesh=trimesh.Trimesh(),
        plate_radius=devices.cell.plate_radius,
        fov_y=float(2.0 * np.arctan2(k.height / 2.0, k.fy)),
        aspect=k.width / k.height,
    )


def journal_timeline(directory: Path) -> tuple[list[TimelineStep], SceneData]:
    """The timeline of the session journaled in ``directory`` (replayed here, in :func:`replay_cell`) and its
    empty scene (:func:`journal_scene`): what ``nbv record`` plays. ValueError for a journal without a frame or
    one that cannot be replayed."""
    journal = read_journal(directory)
    if not any(e.get("frame") for e in journal.of_kind("capture")):
        raise ValueError(f"{directory}: no journaled view to record")
    return timeline_of(journal, replay_cell(journal)), journal_scene(journal)
