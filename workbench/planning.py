"""Planning in a cell: the planner asked with the cell's view of the world, the one way a session, a rebuild
and a headless scan ask for a plan (so a resumed or replayed session re-makes exactly the plans it made)."""

from __future__ import annotations

from collections.abc import Sequence

from devices.cell import ScanCell
from planner import CameraPath, Candidate, Planner, PlanResult
from planner.progress import ProgressFn
from planner.types import MovePaths


def plan_in(cell: ScanCell, planner: Planner, progress: ProgressFn | None = None) -> PlanResult:
    """``planner.plan`` with ``cell``'s reachability, the object's box for its collision checks
    (``cell.set_object_box``: nothing to do for the reach sphere), the move times the selection may trade against
    (``cell.move_costs``, used when ``selection.move_cost_weight`` > 0) and the move times between views the
    ``tour`` planner orders its tour by (``cell.move_times``; none from a cell that does not know where its camera
    is, ``cell.knows_pose``: a worker's device-less reach-sphere cell) and the cell's own candidate views, if it
    has them (``cell.candidate_poses``: a recorded set's), and the camera's path on the moves when the cell captures
    during them (:func:`move_paths_of`). ValueError before the first frame.
    progress: the plan's stages as it goes (``Planner.plan``)."""
    if planner.voxel_map.bbox is not None:
        cell.set_object_box(planner.voxel_map.bbox)  # the arm keeps clear of the object's (padded) box
    return planner.plan(
        reachable=cell.is_reachable,
        move_cost=cell.move_costs,
        progress=progress,
        move_times=cell.move_times if cell.knows_pose else None,
        candidate_poses=cell.candidate_poses(),
        move_paths=move_paths_of(cell),
    )


def move_paths_of(cell: ScanCell) -> MovePaths | None:
    """The camera paths of the moves the planner may count (``planner.paths``), when ``cell`` captures during its
    moves (``cell.config.move_capture_hz`` > 0) and knows where its camera is: ``cell.move_paths`` with frames at
    the planner's rate (``path.sample_hz``), at most the cell's own. None otherwise: a path sees nothing."""
    hz = float(cell.config.move_capture_hz)
    if hz <= 0 or not cell.knows_pose:
        return None

    def move_paths(candidates: Sequence[Candidate], indices: Sequence[int], rate: float) -> list[CameraPath | None]:
        return cell.move_paths(candidates, indices, min(rate, hz))

    return move_paths
