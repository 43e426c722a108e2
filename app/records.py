"""What a session remembers: every view, plan, decision and metric, as JSON-ready dicts.

``SessionLog`` is append-only and plain data, so the export is a dump of it and a
journal (issue 6) can write each entry as it is appended.
"""

from __future__ import annotations

import time
from typing import Any

from planner import PlanResult
from planner.planner import IntegrationReport

EXPORT_VERSION = 1


class SessionLog:
    """Append-only record of one session. Not locked: the Workbench calls it under its lock."""

    def __init__(self, session_id: str, model: str, config: dict[str, Any], seed: int) -> None:
        self.session_id = session_id
        self.model = model
        self.config = config
        self.seed = seed
        self.created = time.time()
        self.iterations: list[dict[str, Any]] = []
        self.plans: list[dict[str, Any]] = []
        self.decisions: list[dict[str, Any]] = []
        self.events: list[dict[str, Any]] = []

    def event(self, kind: str, **data: Any) -> dict[str, Any]:
        entry = {"time": time.time(), "kind": kind, **data}
        self.events.append(entry)
        return entry

    def iteration(self, report: IntegrationReport, coverage: float | None, decision: dict[str, Any]) -> dict[str, Any]:
        """Record one integrated view; returns the record (plan fields are filled by :meth:`plan`)."""
        reg = report.registration
        record = {
            "iteration": report.iteration,
            "time": time.time(),
            "pose": report.T_world_camera.to_dict(),
            "decision": decision.get("kind"),
            "plan_id": decision.get("plan_id"),
            "points_frame": report.n_points_frame,
            "points": report.n_points_total,
            "growth": report.growth,
            "coverage": coverage,
            "registration": None
            if reg is None
            else {"accepted": reg.accepted, "fitness": reg.fitness, "rmse": reg.rmse, "reason": reg.reason},
            "timings": {k: float(v) for k, v in report.timings.items()},
            "plan_seconds": None,
        }
        self.iterations.append(record)
        return record

    def plan(self, plan_id: str, plan: PlanResult) -> dict[str, Any]:
        """Record a plan; its time also goes on the record of the iteration it was made at."""
        seconds = float(sum(plan.timings.values()))
        best = plan.best_index
        entry = {
            "plan_id": plan_id,
            "time": time.time(),
            "iteration": plan.iteration,
            "best_index": best,
            "best_score": None if best is None else float(plan.scores[best].score),
            "best_pose": None if best is None else plan.candidates[best].T_world_camera.to_dict(),
            "seconds": seconds,
            "timings": {k: float(v) for k, v in plan.timings.items()},
            "n_candidates": len(plan.candidates),
            "n_eligible": int(sum(s.eligible for s in plan.scores)),
            "n_ellipsoids": {"occupied": len(plan.occupied_ellipsoids), "frontier": len(plan.frontier_ellipsoids)},
            "fits": [fit_json(f) for f in plan.fits],
            "terminated": plan.terminated,
        }
        self.plans.append(entry)
        for record in reversed(self.iterations):
            if record["iteration"] == plan.iteration:
                record["plan_seconds"] = seconds
                break
        return entry

    def decision(self, decision: dict[str, Any]) -> dict[str, Any]:
        entry = {"time": time.time(), **decision}
        self.decisions.append(entry)
        return entry

    def metrics(self) -> dict[str, Any]:
        """Per-iteration series for the charts and the BIC curves of the last plan."""
        last = self.plans[-1] if self.plans else None
        return {
            "iterations": [
                {k: r[k] for k in ("iteration", "coverage", "points", "plan_seconds", "decision")}
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
        }


def fit_json(fit: Any) -> dict[str, Any]:
    """A ClusterFit as ``{"kind", "t_chosen", "n_points", "seconds", "bic": [[t, bic], ...]}``."""
    return {
        "kind": fit.kind,
        "t_chosen": int(fit.t_chosen),
        "n_points": int(fit.n_points),
        "seconds": float(fit.seconds),
        "bic": [[int(t), float(b)] for t, b in fit.bic],
    }
