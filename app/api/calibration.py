"""Calibrations as resources: commission a cell (hand-eye transform and turntable axis) pose by pose.

Each calibration (workbench/calibration/) runs on its own cell: simulated with a calibration error model, or the
server's hardware (its cell file). The page previews a pose (the ghost arm plays the move in the calibration's
3D view), approves or skips it, reads each capture's residual and the estimate with its uncertainty, and asks
for the write into the cell file (the old file kept as a backup). An unreachable pose, or one whose frame shows
no sphere, is skipped with its reason (200, the calibration goes on); 409 for a captured pose, a busy
calibration or a write without an estimate or a cell file; 422 for a bad request or no estimate possible yet;
503 for a device fault (the pose stays pending) or a cell file that cannot be written.
"""

from __future__ import annotations

from typing import Annotated, Any

from fastapi import APIRouter, Depends, Request, Response
from pydantic import BaseModel, ConfigDict, Field, StrictBool, StrictInt, StrictStr

from app.api.deps import Scene, Settings
from app.api.viewer import viewer_ticket
from app.schemas import Number, ViewerTicketOut
from workbench import CalibrationRun, Calibrations, Conflict

router = APIRouter(prefix="/calibrations", tags=["calibration"])


def calibrations_of(request: Request) -> Calibrations:
    calibrations = getattr(request.app.state, "calibrations", None)
    if calibrations is None:
        raise Conflict("calibrations are not available on this server (not started)")
    return calibrations


CalibrationsDep = Annotated[Calibrations, Depends(calibrations_of)]


def run_of(calibration_id: str, calibrations: CalibrationsDep) -> CalibrationRun:
    return calibrations.get(calibration_id)


RunDep = Annotated[CalibrationRun, Depends(run_of)]


class CalibrationRequest(BaseModel):
    """A new calibration: ``kind`` 'sim' (a simulated cell with ``sensor`` and ``calibration`` error models drawn
    from ``seed``) or 'hardware' (the server's cell file; ``dry_run``: the simulator on its arm model). Default:
    'hardware' on a server with a cell file, else 'sim'. ``plate_angles_deg`` and ``views`` (1..6 per angle)
    choose fewer poses than the routine's 36."""

    model_config = ConfigDict(extra="forbid")
    kind: StrictStr | None = None
    sensor: StrictStr | None = None
    calibration: StrictStr | None = None
    seed: StrictInt = Field(0, ge=0)
    dry_run: StrictBool | None = None
    plate_angles_deg: list[Number] | None = Field(None, min_length=1, max_length=12)
    views: StrictInt | None = Field(None, ge=1, le=6)


class EstimateRequest(BaseModel):
    model_config = ConfigDict(extra="forbid")
    angle_sigma_deg: Number | None = Field(None, ge=0.0, le=5.0)


class PoseOut(BaseModel):
    """One pose: its status (pending, captured, skipped) and why; the spheres fitted and each fit's RMS (mm, null:
    not seen); the capture's RMS centre residual under the latest estimate (mm)."""

    index: int
    label: str
    plate_angle_deg: float
    status: str
    reason: str | None
    spheres: int
    fit_rms_mm: list[float | None]
    residual_mm: float | None


class EstimateOut(BaseModel):
    """The estimate (devices/calibration/result.py ``CalibrationResult.to_json``); *_std: one sigma, the residuals'
    (scaled by their reduced chi-square) plus the error budget's (the arm's repeatability, a centre bias); *_bound95:
    the error's norm stays below it in 95 % of calibrations."""

    T_flange_camera: list[list[float]]
    hand_eye_translation: list[float]
    hand_eye_rotation_deg: list[float]
    axis_point: list[float]
    axis_direction: list[float]
    axis_tilt_deg: float
    hand_eye_std_mm: float
    hand_eye_std_deg: float
    axis_std_mm: float
    axis_std_deg: float
    hand_eye_bound95_mm: float
    hand_eye_bound95_deg: float
    axis_bound95_mm: float
    axis_bound95_deg: float
    rms_mm: float
    residuals_mm: dict[str, float]


class TruthOut(BaseModel):
    """A simulated cell's check: the estimate's errors against the drawn truth, and the nominal values' errors."""

    hand_eye_error_mm: float
    hand_eye_error_deg: float
    axis_error_mm: float
    axis_error_deg: float
    nominal_error: dict[str, float]


class WrittenOut(BaseModel):
    path: str
    backup: str


class CalibrationOut(BaseModel):
    """A calibration's status: its poses, the estimate (or in ``note`` why there is none yet), the write."""

    id: str
    source: dict[str, Any]
    busy: str | None
    writable: bool
    target: dict[str, float]
    poses: list[PoseOut]
    selected: int | None
    counts: dict[str, int]
    estimate: EstimateOut | None
    note: str
    written: WrittenOut | None
    truth: TruthOut | None


class CalibrationItem(BaseModel):
    id: str
    source: dict[str, Any]
    counts: dict[str, int]


class PreviewOut(BaseModel):
    """The move to a pose from where the arm stands (nothing moved): joints, plate angle, seconds; or why not."""

    index: int
    reachable: bool
    reason: str | None
    joints: list[float] | None
    plate_angle_deg: float | None
    duration: float | None
    tabs: int


@router.get("", response_model=list[CalibrationItem])
def list_calibrations(calibrations: CalibrationsDep) -> list[dict[str, Any]]:
    out = []
    for run in calibrations.list():
        status = run.status()
        out.append({"id": run.id, "source": status["source"], "counts": status["counts"]})
    return out


@router.post("", response_model=CalibrationOut, status_code=201)
def create_calibration(body: CalibrationRequest, calibrations: CalibrationsDep) -> dict[str, Any]:
    """Open a calibration (the target on the plate: docs/hardware.md, "Commissioning a cell")."""
    return calibrations.create(body.model_dump(exclude_none=True)).status()


@router.get("/{calibration_id}", response_model=CalibrationOut)
def calibration_status(run: RunDep) -> dict[str, Any]:
    return run.status()


@router.delete("/{calibration_id}", status_code=204)
def close_calibration(calibration_id: str, calibrations: CalibrationsDep) -> Response:
    """Close it and release its cell's devices (the estimate is gone unless written)."""
    calibrations.close(calibration_id)
    return Response(status_code=204)


@router.post("/{calibration_id}/poses/{index}/preview", response_model=PreviewOut)
def preview_pose(run: RunDep, index: int, request: Request) -> dict[str, Any]:
    """Plan the move to pose ``index`` from where the arm stands and play it on the ghost arm in every tab showing
    this calibration (nothing moves); an unreachable pose answers ``reachable: false`` and the reason."""
    preview = run.preview(index)
    views = getattr(request.app.state, "calibration_views", None)
    tabs = 0 if views is None else views.play_preview(run, preview)
    return {**preview.to_json(), "tabs": tabs}


@router.post("/{calibration_id}/poses/{index}/approve", response_model=CalibrationOut)
def approve_pose(run: RunDep, index: int) -> dict[str, Any]:
    """Move to pose ``index``, capture, fit the spheres, redo the estimate. An unreachable pose or one with no
    sphere in view is skipped (its reason in the pose)."""
    run.approve(index)
    return run.status()


@router.post("/{calibration_id}/poses/{index}/skip", response_model=CalibrationOut)
def skip_pose(run: RunDep, index: int) -> dict[str, Any]:
    run.skip(index)
    return run.status()


@router.post("/{calibration_id}/estimate", response_model=CalibrationOut)
def estimate(run: RunDep, body: EstimateRequest | None = None) -> dict[str, Any]:
    """Redo the estimate (``angle_sigma_deg``: the plate angle's error per move; 0: exact); 422 saying what is
    missing when the captures cannot give one."""
    run.estimate(None if body is None else body.angle_sigma_deg)
    return run.status()


@router.post("/{calibration_id}/write", response_model=WrittenOut)
def write_cell_file(run: RunDep) -> dict[str, str]:
    """Write the estimate into the server's cell file (``[devices.hand_eye]``, ``[devices.arm_base]`` and
    ``[devices.turntable_axis]``); the old file is kept as ``<name>.<UTC time>.bak``. Sessions opened afterwards
    use the new values."""
    return run.write()


@router.post("/{calibration_id}/viewer", response_model=ViewerTicketOut, status_code=201)
def open_viewer(run: RunDep, request: Request, settings: Settings, scene: Scene) -> dict[str, Any]:
    """A 3D viewer of this calibration for one tab (a single-use ticket, as for a session's viewer): the plate,
    the target, every pose's camera (grey pending, green captured, red skipped), the arm and the previewed move."""
    return viewer_ticket(request, settings, scene, run.id)


routers = [router]
