"""PlanResult pieces as JSON-ready dicts, and a JSON response that never fails on NaN or inf."""

from __future__ import annotations

import json
import math
from typing import Any

from fastapi.responses import JSONResponse

from planner import PlanResult
from workbench import jsonable


class SafeJSONResponse(JSONResponse):
    """JSON where NaN / inf become null (the standard encoder would refuse them with a 500)."""

    def render(self, content: Any) -> bytes:
        return json.dumps(jsonable(content), ensure_ascii=False, separators=(",", ":")).encode("utf-8")


def candidate_json(plan: PlanResult, i: int) -> dict[str, Any]:
    """``{"index", "pose", "score", "eligible", "frontier", "occupied", ...}`` of candidate ``i``; ``move_seconds``
    the estimated move from the current state (None when the plan has no move times or the move is unknown),
    ``tour_order`` its place (1-based) in the ``tour`` planner's predicted tour and ``tour_seconds`` the predicted
    move seconds from now until it is reached, ``tour_method`` how the tour was made ("ring": a view of the ring
    opening, ``tour.opening``; "exact" or "lkh": the cover's order; "near": ``tour.score = "projection"``) (all three
    None off the tour)."""
    c, s = plan.candidates[i], plan.scores[i]
    move = None if plan.move_costs is None else float(plan.move_costs[i])
    order = plan.tour.views.index(i) if plan.tour is not None and i in plan.tour.views else None
    return {
        "index": i,
        "pose": c.T_world_camera.to_dict(),
        "score": float(s.score),
        "eligible": bool(s.eligible),
        "frontier": float(s.frontier),
        "occupied": float(s.occupied),
        "sector": int(c.sector),
        "elevation_deg": math.degrees(c.elevation),
        "azimuth_deg": math.degrees(c.azimuth),
        "best": plan.best_index == i,
        "reason": plan.ineligible_reasons[i] if plan.ineligible_reasons else ("" if s.eligible else "ineligible"),
        "move_seconds": move if move is not None and math.isfinite(move) else None,
        "tour_order": None if order is None else order + 1,
        "tour_seconds": None if order is None or plan.tour is None else plan.tour.seconds[order],
        "tour_method": None if order is None or plan.tour is None else plan.tour.method,
    }


def ellipsoid_labels(plan: PlanResult) -> list[str]:
    """``O0, O1, ..., F0, F1, ...``: kind initial and index within the kind, in PlanResult order."""
    counters = {"occupied": 0, "frontier": 0}
    labels = []
    for e in plan.ellipsoids:
        labels.append(f"{e.kind[0].upper()}{counters[e.kind]}")
        counters[e.kind] += 1
    return labels


def candidate_detail(plan: PlanResult, plan_id: str, i: int) -> dict[str, Any]:
    """The candidate plus its score breakdown per ellipsoid (rank, weight, pixels, weighted pixels)."""
    s = plan.scores[i]
    terms = []
    per = len(s.ranks) == len(plan.ellipsoids)
    for j, (e, label) in enumerate(zip(plan.ellipsoids, ellipsoid_labels(plan), strict=True)):
        terms.append(
            {
                "index": j,
                "kind": e.kind,
                "label": label,
                "center": e.center.tolist(),
                "axes": e.axes.tolist(),
                "rank": int(s.ranks[j]) if per else -1,
                "weight": float(s.weights[j]) if per else 0.0,
                "pixels": float(s.pixels[j]) if per else 0.0,
                "weighted": float(s.weighted[j]) if per else 0.0,
            }
        )
    return {**candidate_json(plan, i), "plan_id": plan_id, "ellipsoids": terms}
