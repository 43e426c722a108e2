"""Request and response bodies of the REST API (pydantic). Out-of-range values are 422s here."""

from __future__ import annotations

import math
from typing import Annotated, Any

from pydantic import AfterValidator, BaseModel, ConfigDict, Field, model_validator

from planner import Pose


def _finite(values: list[float]) -> list[float]:
    if not all(math.isfinite(v) for v in values):
        raise ValueError("must be finite numbers")
    return values


def _unit(values: list[float]) -> list[float]:
    if math.sqrt(sum(v * v for v in values)) < 1e-9:
        raise ValueError("quaternion must not be zero")
    return values


Vec3 = Annotated[list[float], Field(min_length=3, max_length=3), AfterValidator(_finite)]
Quat = Annotated[list[float], Field(min_length=4, max_length=4), AfterValidator(_finite), AfterValidator(_unit)]


class PoseModel(BaseModel):
    """A camera pose ``T_world_camera`` in the planner's world (turntable) frame, OpenCV camera axes."""

    model_config = ConfigDict(extra="forbid")
    position: Vec3 = Field(description="camera centre, metres")
    wxyz: Quat = Field(description="orientation quaternion (w, x, y, z); normalised on use")

    def to_pose(self) -> Pose:
        return Pose.from_wxyz(self.wxyz, self.position)


class SessionCreate(BaseModel):
    model_config = ConfigDict(extra="forbid")
    model: str | None = Field(
        default=None, max_length=200, description="a name from GET /api/models (default: the server's)"
    )
    config: dict[str, Any] = Field(
        default_factory=dict,
        description='any subset of the planner config, e.g. {"voxel": {"resolution": 0.02}, "cluster": {"t_max": 10}}',
    )
    seed: int = Field(default=0, ge=0, le=2**32 - 1, description="seeds the planner's fits and the simulated noise")


class SessionCreated(BaseModel):
    id: str


class BestView(BaseModel):
    index: int
    pose: PoseModel
    score: float


class PlanOut(BaseModel):
    plan_id: str
    iteration: int
    best: BestView | None
    timings: dict[str, float]
    n_candidates: int
    n_eligible: int
    terminated: str | None = None


class CustomPoseOut(BaseModel):
    pose: PoseModel
    reachable: bool
    reason: str


class SessionOut(BaseModel):
    id: str
    model: str
    state: str
    iteration: int
    coverage: float | None
    points: int
    pending_plan: PlanOut | None
    selected: int | None
    custom_pose: CustomPoseOut | None
    error: str | None
    terminated: str | None
    auto_remaining: int
    moves: int
    seed: int


class CandidateOut(BaseModel):
    index: int
    pose: PoseModel
    score: float
    eligible: bool
    frontier: float
    occupied: float
    sector: int
    elevation_deg: float
    azimuth_deg: float
    best: bool


class EllipsoidTerm(BaseModel):
    index: int = Field(description="position in PlanResult.ellipsoids (occupied first, then frontier)")
    kind: str
    label: str = Field(description="O3 / F0: kind initial and index within the kind")
    center: list[float]
    axes: list[float]
    rank: int = Field(description="depth rank in this camera, -1 when behind it")
    weight: float
    pixels: float
    weighted: float


class CandidateDetail(CandidateOut):
    plan_id: str
    ellipsoids: list[EllipsoidTerm]


class ApproveRequest(BaseModel):
    """Exactly one of ``index`` (a candidate of the plan) or ``pose`` (a custom view)."""

    model_config = ConfigDict(extra="forbid")
    plan_id: str = Field(max_length=64)
    index: int | None = Field(default=None, ge=0)
    pose: PoseModel | None = None

    @model_validator(mode="after")
    def _one_target(self) -> ApproveRequest:
        if (self.index is None) == (self.pose is None):
            raise ValueError("give exactly one of 'index' or 'pose'")
        return self


class IterationOut(BaseModel):
    iteration: int
    pose: PoseModel
    decision: str | None
    plan_id: str | None
    points_frame: int
    points: int
    growth: float | None
    coverage: float | None
    plan_seconds: float | None


class StepRequest(BaseModel):
    model_config = ConfigDict(extra="forbid")
    count: int = Field(default=1, ge=1, le=100)


class AutoRequest(BaseModel):
    model_config = ConfigDict(extra="forbid")
    count: int = Field(default=5, ge=1, le=100, description="steps to run unless stopped")


class SelectRequest(BaseModel):
    model_config = ConfigDict(extra="forbid")
    index: int = Field(ge=0)


class CustomPoseRequest(BaseModel):
    model_config = ConfigDict(extra="forbid")
    pose: PoseModel


class FocusRequest(BaseModel):
    model_config = ConfigDict(extra="forbid")
    session: str | None = Field(description="the session the 3D view shows (null: none)")


class CameraRequest(BaseModel):
    """Either ``candidate`` (look at that candidate from outside the hemisphere) or ``position`` + ``look_at``."""

    model_config = ConfigDict(extra="forbid")
    candidate: int | None = Field(default=None, ge=0)
    distance: float = Field(default=0.3, gt=0, le=5)
    position: Vec3 | None = None
    look_at: Vec3 | None = None

    @model_validator(mode="after")
    def _one_target(self) -> CameraRequest:
        if (self.candidate is None) == (self.position is None or self.look_at is None):
            raise ValueError("give either 'candidate' or both 'position' and 'look_at'")
        return self


class ModelOut(BaseModel):
    name: str
    kind: str
    description: str


class ViewerOut(BaseModel):
    url: str
    port: int
