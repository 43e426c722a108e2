"""What a session remembers, derived from its journal's events in one place.

A live session feeds every event it journals to :meth:`SessionRecord.apply` as it appends it; a rebuild
(workbench/journal/rebuild.py) and an interrupted session's listing feed the events they read. So the
export, the charts, the status and the rebuild all read one record of one shape. Not locked: the session
calls it under its lock.
"""

from __future__ import annotations

from typing import Any

from workbench.session.summaries import VIEW_ACCURACY

EXPORT_VERSION = 1
REFUSAL_KEYS = ("plan_id", "candidate", "reason", "message", "next")
"""A ``refused`` event's fields: the plan and candidate refused, why, and the candidate taken instead."""
HEADER_KINDS = ("session", "resume")
"""Events that describe the journal rather than the scan; they are not listed among the record's events."""


class SessionRecord:
    """Append-only record of one session: iterations, plans, decisions and other events, JSON-ready."""

    def __init__(self, session_id: str, model: str, config: dict[str, Any], seed: int, created: float) -> None:
        self.session_id = session_id
        self.model = model
        self.config = config
        self.seed = seed
        self.created = created
        self.guided = False
        """Guided mode (the page explains each step; a class's seats): the journal header's ``guided``."""
        self.iterations: list[dict[str, Any]] = []
        self.plans: list[dict[str, Any]] = []
        self.decisions: list[dict[str, Any]] = []
        self.events: list[dict[str, Any]] = []
        self.voxels: dict[str, int] = {"occupied": 0, "frontier": 0, "unknown": 0, "empty": 0}
        self.refusals: list[dict[str, Any]] = []
        """Every move the cell refused or frame the planner could not use, of the planner's choices (in order)."""
        self._refused_since: list[dict[str, Any]] = []  # the refusals before the next view

    @classmethod
    def from_header(cls, header: dict[str, Any]) -> SessionRecord:
        """An empty record for the journal whose ``session`` event is ``header``."""
        record = cls(
            str(header["id"]), str(header["model"]["name"]), header["config"], int(header["seed"]), header["time"]
        )
        record.guided = header.get("guided") is True  # journals without it: not guided
        return record

    def apply(self, event: dict[str, Any]) -> None:
        """Take one journal event ``{"seq", "time", "kind", ...}`` into the record."""
        kind = event["kind"]
        if kind == "capture":
            self._capture(event)
        elif kind == "plan":
            self._plan(event)
        elif kind == "decision":
            fields = {k: v for k, v in event.items() if k not in ("seq", "kind", "decision")}
            self.decisions.append({**fields, "kind": event["decision"]})
        elif kind not in HEADER_KINDS:
            if kind == "refused":
                refusal = {k: event.get(k) for k in REFUSAL_KEYS}
                self.refusals.append(refusal)
                self._refused_since.append(refusal)
            if kind == "config":
                self.config = event["config"]
            self.events.append({k: v for k, v in event.items() if k != "seq"})

    def _capture(self, ev: dict[str, Any]) -> None:
        self.iterations.append(
            {
                "iteration": ev["iteration"],
                "time": ev["time"],
                "pose": ev.get("pose_used", ev.get("pose")),
                "decision": ev.get("decision"),
                "plan_id": ev.get("plan_id"),
                "points_frame": ev.get("points_frame"),
                "points": ev["points"],
                "growth": ev.get("growth"),
                "coverage": ev.get("coverage"),
                "surface_fscore_5mm": ev.get("surface_fscore_5mm"),
                "registration": ev.get("registration"),
                "accuracy": ev.get("accuracy"),
                "refused": self._refused_since,
                "timings": ev.get("timings", {}),
                "plan_seconds": None,
                "move_seconds": ev.get("move_seconds"),
                "capture_seconds": ev.get("capture_seconds"),
                "robot_seconds": None,
                "move_frames": len(ev.get("move_frames") or []),
                "move_capture": ev.get("move_capture"),
            }
        )
        self._refused_since = []
        if ev.get("voxels") is not None:
            self.voxels = dict(ev["voxels"])

    def _plan(self, ev: dict[str, Any]) -> None:
        best = ev.get("best")
        seconds = float(sum(ev.get("timings", {}).values()))
        self.plans.append(
            {
                "plan_id": ev["plan_id"],
                "time": ev["time"],
                "iteration": ev["iteration"],
                "best_index": None if best is None else best["index"],
                "best_score": None if best is None else best["score"],
                "best_pose": None if best is None else best["pose"],
                "seconds": seconds,
                "timings": ev.get("timings", {}),
                "n_candidates": ev.get("n_candidates"),
                "n_eligible": ev.get("n_eligible"),
                "n_ellipsoids": ev.get("n_ellipsoids"),
                "fits": ev.get("fits", []),
                "terminated": ev.get("terminated"),
            }
        )
        for record in reversed(self.iterations):  # the plan's time also goes on the view it was made at
            if record["iteration"] == ev["iteration"]:
                record["plan_seconds"] = seconds
                if record.get("move_seconds") is not None:  # the view's robot time: move, capture, plan
                    record["robot_seconds"] = record["move_seconds"] + (record.get("capture_seconds") or 0.0) + seconds
                break

    def metrics(self) -> dict[str, Any]:
        """Per-iteration series for the charts and the BIC curves of the last plan."""
        last = self.plans[-1] if self.plans else None
        return {
            "iterations": [
                {k: r[k] for k in ("iteration", "coverage", "points", "plan_seconds", "decision")}
                | {"robot_seconds": r.get("robot_seconds")}
                | {"surface_fscore_5mm": r.get("surface_fscore_5mm")}
                | {k: (r.get("accuracy") or {}).get(k) for k in VIEW_ACCURACY}
                for r in self.iterations
            ],
            "fits": [] if last is None else last["fits"],
            "fit_iteration": None if last is None else last["iteration"],
        }

    def export(self, status: dict[str, Any]) -> dict[str, Any]:
        """The whole session as one JSON document (format version ``EXPORT_VERSION``)."""
        return {
            "version": EXPORT_VERSION,
            "session": status,
            "model": self.model,
            "seed": self.seed,
            "created": self.created,
            "config": self.config,
            "iterations": list(self.iterations),
            "plans": list(self.plans),
            "decisions": list(self.decisions),
            "events": list(self.events),
            "refusals": list(self.refusals),
        }
