"""The fit at another T: one voxel kind of a session's plan clustered again at a chosen T, for inspection only.

The voxels are those of the pending (else the last) plan; the job (``Session.refit``) runs in the session's
worker (in this process for a session without one) under the plan budget. Nothing of the session changes: not its state,
not its plan, not the fitter's warm start (the planner's next fit is the one it would have made anyway).
"""

from __future__ import annotations

from dataclasses import dataclass

from planner import ClusterFit, Ellipsoid
from planner.types import EllipsoidKind

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
