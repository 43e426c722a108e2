"""The fit at another T: one voxel kind of a session's plan clustered again at a chosen T, for inspection only.

The voxels are those of the pending (else the last) plan; the job runs in the session's worker (in this
process for a session without one) under the plan budget. Nothing of the session changes: not its state,
not its plan, not the fitter's warm start (the planner's next fit is the one it would have made anyway).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import TYPE_CHECKING

from planner import ClusterFit, Ellipsoid
from planner.ellipsoids import fit_at_t
from planner.types import EllipsoidKind
from workbench.errors import Conflict, Invalid
from workbench.workers.client import JobKilled

if TYPE_CHECKING:
    from workbench.session.core import SessionCore

KINDS: tuple[EllipsoidKind, ...] = ("occupied", "frontier")


@dataclass(frozen=True, eq=False)
class Refit:
    """``kind``'s voxels of plan ``plan_id`` fitted at ``t`` components: ellipsoids (this kind's, by component) and
    the fit (its ``labels`` index ``ellipsoids`` per voxel of ``PlanResult.voxels``; ``bic``: ((t, BIC),))."""

    plan_id: str
    kind: EllipsoidKind
    t: int
    ellipsoids: tuple[Ellipsoid, ...]
    fit: ClusterFit


def refit(s: SessionCore, kind: str, t: int) -> Refit:
    """Fit ``kind``'s voxels of the session's current plan at ``t`` components (see the module docstring).

    Invalid for an unknown kind or a T outside [1, min(voxels, max(t_max, the plan's T))]; Conflict without a
    plan, or when the worker job is killed (budget, Stop, DELETE)."""
    if kind not in KINDS:
        raise Invalid(f"kind: must be one of {', '.join(KINDS)}, got {kind!r}")
    entry = s.plan_for()
    plan = entry.plan
    points = plan.voxels.occupied if kind == "occupied" else plan.voxels.frontier
    chosen = max((f.t_chosen for f in plan.fits if f.kind == kind), default=0)
    t_hi = min(len(points), max(s.config.cluster.t_max, chosen))
    if isinstance(t, bool) or not isinstance(t, int) or not 1 <= t <= t_hi:
        raise Invalid(f"t: must be an integer in [1, {t_hi}] for the {len(points)} {kind} voxels, got {t!r}")
    payload = (points, s.config.cluster, plan.voxels.resolution, kind, t)
    try:
        if s.worker is None:
            ellipsoids, fit = fit_at_t(*payload)
        else:
            ellipsoids, fit = s.worker.call("fit", payload, s.plan_budget, f"the {kind} fit at T={t}")
    except JobKilled as exc:
        raise Conflict(f"session {s.id}: {exc}") from None
    return Refit(entry.plan_id, kind, t, tuple(ellipsoids), fit)  # type: ignore[arg-type]
