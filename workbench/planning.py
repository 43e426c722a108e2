"""Planning in a cell: the planner asked with the cell's view of the world, the one way a session, a rebuild
and a headless scan ask for a plan (so a resumed or replayed session re-makes exactly the plans it made)."""

from __future__ import annotations

from devices.cell import ScanCell
from planner import Planner, PlanResult
from planner.progress import ProgressFn


def plan_in(cell: ScanCell, planner: Planner, progress: ProgressFn | None = None) -> PlanResult:
    """``planner.plan`` with ``cell``'s reachability, the object's box for its collision checks
    (``cell.set_object_box``: nothing to do for the reach sphere), the move times the selection may trade against
    (``cell.move_costs``, used when ``selection.move_cost_weight`` > 0) and the move times between views the
    ``tour`` planner orders its tour by (``cell.move_times``; none from a cell that does not know where its camera
    is, ``cell.knows_pose``: a worker's device-less reach-sphere cell) and the cell's own candidate views, if it
    has them (``cell.candidate_poses``: a recorded set's). ValueError before the first frame.
    progress: the plan's stages as it goes (``Planner.plan``)."""
    if planner.voxel_map.bbox is not None:
        cell.set_object_box(planner.voxel_map.bbox)  # the arm keeps clear of the object's (padded) box
    return planner.plan(
        reachable=cell.is_reachable,
        move_cost=cell.move_costs,
        progress=progress,
        move_times=cell.move_times if cell.knows_pose else None,
        candidate_poses=cell.candidate_poses(),
    )
