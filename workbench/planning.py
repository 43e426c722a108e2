"""Planning in a cell: the planner asked with the cell's view of the world, the one way a session, a rebuild
and a headless scan ask for a plan (so a resumed or replayed session re-makes exactly the plans it made)."""

from __future__ import annotations

from typing import Any

from planner import Planner, PlanResult
from planner.progress import ProgressFn


def plan_in(cell: Any, planner: Planner, progress: ProgressFn | None = None) -> PlanResult:
    """``planner.plan`` with ``cell``'s reachability and, for a cell with an arm, the object's box for its
    collision checks (``cell.set_object_box``) and the move times the selection may trade against
    (``cell.move_costs``, used when ``selection.move_cost_weight`` > 0) and the move times between views the
    ``tour`` planner orders its tour by (``cell.move_times``; none from a worker's device-less reach-sphere
    cell, which knows no camera pose). ValueError before the first frame.
    progress: the plan's stages as it goes (``Planner.plan``)."""
    set_box = getattr(cell, "set_object_box", None)
    if callable(set_box) and planner.voxel_map.bbox is not None:
        set_box(planner.voxel_map.bbox)  # the arm keeps clear of the object's (padded) box
    return planner.plan(
        reachable=cell.is_reachable,
        move_cost=getattr(cell, "move_costs", None),
        progress=progress,
        move_times=getattr(cell, "move_times", None) if getattr(cell, "arm", None) is not None else None,
    )
