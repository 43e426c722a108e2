"""Request and response bodies of the REST API (pydantic). Out-of-range values are 422s here."""

from __future__ import annotations

import copy
import dataclasses
import math
import typing
from typing import Annotated, Any, Literal

from fastapi.encoders import jsonable_encoder
from fastapi.openapi.models import Schema
from pydantic import (
    AfterValidator,
    BaseModel,
    ConfigDict,
    Field,
    StrictBool,
    StrictFloat,
    StrictInt,
    create_model,
    model_validator,
)

from planner import Pose
from planner.types import QUATERNION_ZERO
from workbench import SessionStatus


def _finite(values: list[float | int]) -> list[float]:
    if not all(math.isfinite(v) for v in values):
        raise ValueError("must be finite numbers")
    return [float(v) for v in values]


def _unit(values: list[float]) -> list[float]:
    """The quaternion as given, when it has a direction: its largest component is compared (a sum of squares
    overflows for ``[1e200] * 4`` and underflows for tiny ones); ``Pose.from_wxyz`` normalises it robustly
    (``planner.unit_quaternion``), so the pose used is the one asked for."""
    if max(abs(v) for v in values) < QUATERNION_ZERO:
        raise ValueError("quaternion must not be zero")
    return values


Number = StrictFloat | StrictInt
"""A JSON number: 1 and 0.5, never true or "1" (strict types on everything that can move the robot)."""
Index = Annotated[StrictInt, Field(ge=0)]
"""A candidate index: a JSON integer >= 0, never true, "1" or 1.0."""
Vec3 = Annotated[list[Number], Field(min_length=3, max_length=3), AfterValidator(_finite)]
Quat = Annotated[list[Number], Field(min_length=4, max_length=4), AfterValidator(_finite), AfterValidator(_unit)]


class PoseModel(BaseModel):
    """A camera pose ``T_world_camera`` in the planner's world (turntable) frame, OpenCV camera axes."""

    model_config = ConfigDict(extra="forbid")
    position: Vec3 = Field(description="camera centre, metres")
    wxyz: Quat = Field(description="orientation quaternion (w, x, y, z); normalised on use")

    def to_pose(self) -> Pose:
        return Pose.from_wxyz(self.wxyz, self.position)


class ErrorOut(BaseModel):
    """Every error answer: 4xx / 5xx with one field."""

    detail: str | list[dict[str, Any]] = Field(
        description="why the request was refused: one sentence, or (422 of a malformed request) pydantic's field errors"
    )
    error_id: str | None = Field(default=None, description="500 only: the id of the error in the server log")


ERROR_RESPONSES: dict[int | str, dict[str, Any]] = {
    400: {"description": "a malformed body, a bad Content-Length, or a Host this server refuses"},
    401: {"description": "missing or wrong token (servers started with a token)"},
    403: {"description": "a state-changing request from another origin"},
    404: {"description": "unknown session, candidate, model or recording"},
    409: {"description": "wrong state, a stale or used plan_id, an interrupted session"},
    413: {"description": "request body over the size limit"},
    422: {"description": "bad parameters, an unreachable pose or one inside the object"},
    500: {"description": "an unexpected error; error_id finds it in the server log"},
    503: {
        "description": "a device fault or timeout (the session is in state error, map unchanged), or the data "
        "directory cannot be written",
    },
}
"""The error answers of every /api operation (the API router's ``responses``), each an :class:`ErrorOut` in the
OpenAPI document (:func:`document_error_bodies`). Given here without their ``model``: FastAPI builds the response
fields of every route again for each app that includes the router (on its first requests), and nine models per
route made that 0.074 s of CPU per app instead of 0.024 (the 59 routes, a quiet machine)."""


def document_error_bodies(schema: dict[str, Any]) -> dict[str, Any]:
    """``schema`` (an OpenAPI document of the app) with an :class:`ErrorOut` body on every response of
    :data:`ERROR_RESPONSES` that has none, and ErrorOut among its components: the document FastAPI writes when
    the router's responses name the model."""
    body = {"application/json": {"schema": {"$ref": "#/components/schemas/ErrorOut"}}}
    codes = {str(code) for code in ERROR_RESPONSES}
    for operations in schema.get("paths", {}).values():
        for operation in operations.values():
            for code, response in operation.get("responses", {}).items():
                if code in codes and "content" not in response:
                    response["content"] = copy.deepcopy(body)
    components = schema.setdefault("components", {}).setdefault("schemas", {})
    error_out = ErrorOut.model_json_schema(ref_template="#/components/schemas/{model}", mode="serialization")
    components["ErrorOut"] = jsonable_encoder(Schema(**error_out), by_alias=True, exclude_none=True)  # as FastAPI
    schema["components"]["schemas"] = dict(sorted(components.items()))
    return schema


class BagTopicsIn(BaseModel):
    """Where a ROS 2 bag's scan is (docs/bags.md); each default is realsense2_camera's / ros2_control's name."""

    model_config = ConfigDict(extra="forbid")
    depth: str | None = Field(
        default=None,
        min_length=1,
        max_length=200,
        description="depth images (default /camera/camera/depth/image_rect_raw)",
    )
    camera_info: str | None = Field(
        default=None, min_length=1, max_length=200, description="camera info (default /camera/camera/depth/camera_info)"
    )
    joint_states: str | None = Field(
        default=None, min_length=1, max_length=200, description="joint states (default /joint_states)"
    )
    plate_frame: str | None = Field(
        default=None, min_length=1, max_length=200, description="the plate's TF frame, the views' frame (default plate)"
    )


class SourceIn(BaseModel):
    """Where the session's frames come from: the simulated cell, a replay of recorded / journaled frames, the
    devices of the server's cell file (``hardware``, docs/hardware.md; the default when the server has one), or a
    recorded view set whose views are the only candidates (``recorded``, docs/real-data.md)."""

    model_config = ConfigDict(extra="forbid")
    kind: Literal["sim", "replay", "hardware", "recorded"] = "sim"
    recorded: str | None = Field(
        default=None,
        max_length=64,
        description="recorded: a recorded view set from GET /api/recorded (data_dir/recorded); the planner chooses "
        "among its views",
    )
    recording: str | None = Field(
        default=None, max_length=64, description="replay: a name from GET /api/recordings (data_dir/recordings)"
    )
    session: str | None = Field(default=None, pattern=r"^[0-9a-f]{8}$", description="replay: a journaled session id")
    topics: BagTopicsIn | None = Field(
        default=None, description="replay of a ROS 2 bag: where its scan is (default: realsense2_camera's topics)"
    )
    mode: Literal["sequence", "nearest"] = Field(
        default="sequence", description="replay: frames in order, or the frame nearest the approved pose"
    )
    dry_run: bool | None = Field(
        default=None, description="hardware: plan and approve as usual, capture from the simulator, move no device"
    )
    truth: str | None = Field(
        default=None, max_length=200, description="hardware: the model on the plate, to measure coverage against"
    )

    @model_validator(mode="after")
    def _one_origin(self) -> SourceIn:
        if self.kind == "replay" and (self.recording is None) == (self.session is None):
            raise ValueError("a replay source needs exactly one of 'recording' or 'session'")
        if self.topics is not None and self.recording is None:
            raise ValueError("'topics' go with the replay of a recording (a ROS 2 bag)")
        if self.kind != "replay" and (self.recording is not None or self.session is not None):
            raise ValueError(f"a {self.kind} source takes no 'recording' or 'session'")
        if (self.kind == "recorded") != (self.recorded is not None):
            raise ValueError("a recorded source needs 'recorded' (a set's name); other sources take none")
        if self.kind != "hardware" and (self.dry_run is not None or self.truth is not None):
            raise ValueError(f"a {self.kind} source takes no 'dry_run' or 'truth'")
        return self


class CameraIn(BaseModel):
    model_config = ConfigDict(extra="forbid")
    sensor: str | None = Field(
        default=None, max_length=40, description="the simulated depth sensor (GET /api/sensors; default the server's)"
    )
    calibration: str | None = Field(
        default=None, max_length=40, description="the simulated calibration error (GET /api/sensors)"
    )


class CameraModelsOut(BaseModel):
    sensors: list[str] = Field(description="depth sensor models of the simulated camera, the default first")
    calibrations: list[str] = Field(description="calibration and motion error models, the default first")


class ArmChoice(BaseModel):
    name: str = Field(description="what a create's arm takes")
    title: str = Field(description="the robot")
    dof: int = Field(description="joints the arm moves (0: the reach sphere)")
    default: bool = Field(description="the server's default arm")
    note: str = Field(description="what it is, what it suits")


class ArmsOut(BaseModel):
    arms: list[ArmChoice] = Field(description="the arm presets, then the reach sphere")


class SessionCreate(BaseModel):
    model_config = ConfigDict(extra="forbid")
    model: str | None = Field(
        default=None, max_length=200, description="a name from GET /api/models (default: the server's)"
    )
    source: SourceIn | None = Field(
        default=None, description="default: the simulated cell, or the cell file's devices when the server has one"
    )
    faults: dict[str, Any] | None = Field(
        default=None,
        description='fault injection into the devices, e.g. {"schedule": [{"kind": "capture_failure", "at": 3}]} '
        "(default: the server's [faults])",
    )
    config: dict[str, Any] = Field(
        default_factory=dict,
        description='any subset of the planner config, e.g. {"voxel": {"resolution": 0.02}, "cluster": {"t_max": 10}}',
    )
    seed: StrictInt = Field(
        default=0, ge=0, le=2**32 - 1, description="seeds the planner's fits and the simulated noise"
    )
    camera: CameraIn | None = Field(
        default=None,
        description='the simulated camera\'s error models, e.g. {"sensor": "realsense-d435", "calibration": '
        '"typical"} (simulated sessions only; a hardware session refuses them)',
    )
    arm: str | None = Field(
        default=None,
        max_length=40,
        description="the simulated cell's arm: a preset (ur5, ur10, panda, xarm7, z1) or reach_sphere "
        "(GET /api/arms lists them; default the server's)",
    )
    move_capture: float | None = Field(
        default=None,
        ge=0,
        le=60,
        description="capture during moves: depth frames per second taken while the cell moves, integrated like views "
        "(0: off; default the server's devices.cell.move_capture_hz)",
    )
    planner: str = Field(
        default="projection",
        max_length=40,
        description="the view evaluator: projection (the paper's), a ray-casting baseline, or random "
        "(GET /api/planners lists them)",
    )
    progress_id: str | None = Field(
        default=None,
        pattern=r"^[A-Za-z0-9_-]{8,64}$",
        description="names this create: its progress on /api/events?create=ID, DELETE /api/creations/ID cancels it",
    )
    guided: StrictBool = Field(
        default=False, description="guided mode: the page explains each step (journaled; the status's guided)"
    )


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


class ProgressOut(BaseModel):
    operation: str = Field(description="plan, discard, resume (a session's), create")
    stage: str = Field(description='what runs now, e.g. "reachability", "fit occupied", "reading the mesh"')
    step: int = Field(description="the stage's number, 1-based")
    steps: int = Field(description="the operation's stages")
    done: int = Field(description="items of the stage done (candidates, values of T, ...)")
    total: int = Field(description="items of the stage (0: not counted)")
    percent: float = Field(description="of the whole operation, each stage counting the same")
    elapsed: float = Field(description="seconds since the operation started")
    stoppable: bool = Field(description="POST .../stop (a plan) or DELETE /api/creations/{id} (a create) ends it")


def model_of(shape: type, name: str, nested: dict[str, Any]) -> type[BaseModel]:
    """A response schema with the fields, types, defaults and docs of the domain dataclass ``shape``; ``nested``
    gives the schema of a field whose domain type is plain JSON (a dict)."""
    hints = typing.get_type_hints(shape)
    fields: dict[str, Any] = {}
    for f in dataclasses.fields(shape):
        default = ... if f.default is dataclasses.MISSING else f.default
        fields[f.name] = (nested.get(f.name, hints[f.name]), Field(default, description=f.metadata.get("doc")))
    return create_model(name, __doc__=shape.__doc__, **fields)


SessionOut = model_of(
    SessionStatus,
    "SessionOut",
    {"pending_plan": PlanOut | None, "custom_pose": CustomPoseOut | None, "progress": ProgressOut | None},
)
"""A session's status: :class:`workbench.SessionStatus`, the shape defined once in the workbench."""


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
    reason: str = Field(
        description='why it is not eligible: "sector locked", "unreachable", "near a taken view"; "" when eligible'
    )
    move_seconds: float | None = Field(
        None, description="estimated seconds of the move from the current state (plate turn + arm); None: unknown"
    )
    tour_order: int | None = Field(None, description="place (1-based) in the tour planner's predicted tour, or None")
    tour_seconds: float | None = Field(
        None, description="predicted move seconds from now until the tour reaches this view (None off the tour)"
    )
    tour_method: str | None = Field(
        None,
        description='how the tour was made: "ring" (a view of the ring opening, tour.opening), "exact" or "lkh" (the '
        'cover\'s order), "near" (tour.score = "projection"); None off the tour',
    )


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
    plan_id: str = Field(min_length=1, max_length=64)
    index: Index | None = None
    pose: PoseModel | None = None

    @model_validator(mode="after")
    def _one_target(self) -> ApproveRequest:
        if (self.index is None) == (self.pose is None):
            raise ValueError("give exactly one of 'index' or 'pose'")
        return self


class StepRequest(BaseModel):
    model_config = ConfigDict(extra="forbid")
    count: StrictInt = Field(default=1, ge=1, le=100)


class AutoRequest(BaseModel):
    model_config = ConfigDict(extra="forbid")
    count: StrictInt = Field(default=5, ge=1, le=100, description="steps to run unless stopped")


class SelectRequest(BaseModel):
    model_config = ConfigDict(extra="forbid")
    index: Index


class CustomPoseRequest(BaseModel):
    model_config = ConfigDict(extra="forbid")
    pose: PoseModel


class CameraRequest(BaseModel):
    """Either ``candidate`` (look at that candidate from outside the hemisphere) or ``position`` + ``look_at``."""

    model_config = ConfigDict(extra="forbid")
    candidate: Index | None = None
    distance: Number = Field(default=0.3, gt=0, le=5)
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
    note: str | None = None


class ViewerRequest(BaseModel):
    """Open a 3D viewer of one session (one per browser tab)."""

    model_config = ConfigDict(extra="forbid")
    session: str = Field(min_length=1, max_length=64, description="the session this tab's viewer shows")


class ViewerTicketOut(BaseModel):
    """A viewer of one session: ``url`` carries a single-use ticket (valid ``ttl`` seconds until the viewer
    connects); ``viewer`` names it in ``/api/scene/{viewer}`` calls."""

    viewer: str
    session: str
    url: str
    port: int
    ttl: float
    note: str | None = None


class ResumeOut(BaseModel):
    session: SessionOut  # pyright: ignore[reportInvalidTypeForm] # a schema built from the domain's dataclass
    verified: bool = Field(description="every replayed step matched the journal (points, voxels, plans)")
    mismatches: list[str]
    interrupted: str | None = Field(description="plan_id of a decision whose capture never happened; pending again")
    dropped: list[str] = Field(
        default_factory=list,
        description="what a damaged journal lost: the damaged line, event or frame and how much came after it "
        "(the session resumes from just before it; the whole file is kept as journal.damaged-*.jsonl)",
    )


class FaultRequest(BaseModel):
    model_config = ConfigDict(extra="forbid")
    kind: Literal[
        "camera_timeout",
        "capture_failure",
        "nan_frame",
        "empty_frame",
        "arm_halfway",
        "turntable_error",
        "move_refused",
    ]


class DiscardOut(BaseModel):
    discarded: int = Field(description="the iteration the discarded view was")
    mismatches: list[str] = Field(description="where the rebuilt session differs from the journal (none: the same)")
    session: SessionOut  # pyright: ignore[reportInvalidTypeForm] # a schema built from the domain's dataclass


class FaultQueuedOut(BaseModel):
    queued: str = Field(description="the fault kind the device's next action raises")


class MetricPoint(BaseModel):
    iteration: int
    coverage: float | None
    points: int
    plan_seconds: float | None
    decision: str | None
    surface_fscore_5mm: float | None = Field(
        default=None, description="the reconstructed surface's F-score at 5 mm after this view (simulated sessions)"
    )
    precision_5mm: float | None = Field(default=None, description="share of the cloud within 5 mm of the truth")
    fscore_5mm: float | None = Field(default=None, description="F-score of precision and coverage at 5 mm")
    precision_2mm: float | None = None
    fscore_2mm: float | None = None
    chamfer_mm: float | None = None


class MetricsOut(BaseModel):
    """The charts of a session: per-iteration series, the BIC curves of the last plan, the coverage ceiling."""

    iterations: list[MetricPoint]
    fits: list[dict[str, Any]] = Field(description="the last plan's fits: kind, BIC per T, the T chosen")
    fit_iteration: int | None
    ceiling: float | None = Field(description="the reachable-coverage ceiling; null until computed or without truth")
    coverage_ratio: list[float] | None
    auc: float | None
    views_to_90: int | None
    views_to_95: int | None
    views_to_98: int | None


class ExportOut(BaseModel):
    """The whole session as one JSON document (``version``: the export format)."""

    version: int
    session: SessionOut  # pyright: ignore[reportInvalidTypeForm] # a schema built from the domain's dataclass
    model: str
    seed: int
    created: float
    config: dict[str, Any]
    iterations: list[dict[str, Any]]
    plans: list[dict[str, Any]]
    decisions: list[dict[str, Any]]
    events: list[dict[str, Any]]
    surface: dict[str, Any] = Field(
        description="the reconstructed surface: fscore_2mm, fscore_5mm, precision_5mm, recall_5mm, chamfer_mm "
        "(null without a ground truth), triangles, layer_triangles, views, seconds, error (why there is none)"
    )
    refusals: list[dict[str, Any]] = Field(
        default_factory=list, description="the planner's choices refused (plan_id, candidate, reason, message, next)"
    )


class ArmTargetOut(BaseModel):
    kind: str = Field(description="best, selected or custom: which view the move goes to")
    index: int | None
    reachable: bool
    reason: str | None = Field(description="why it is unreachable; null when reachable")
    joints: list[float] | None
    plate_angle: float | None
    duration: float | None
    path_method: str | None


class ArmOut(BaseModel):
    has_arm: bool
    joints: list[float] | None
    plate_angle: float
    target: ArmTargetOut | None
    unreachable: dict[str, str] = Field(description="the cell's reason per unreachable candidate, by index")


class ArmPreviewOut(BaseModel):
    target: ArmTargetOut
    tabs: int = Field(description="tabs animating the ghost arm")
    seconds: float


class ViewerCameraOut(BaseModel):
    client_id: int
    position: list[float]
    wxyz: list[float]
    look_at: list[float]
    fov: float
    image_width: int
    image_height: int
    timestamp: float


class TimelineDecisionOut(BaseModel):
    """The decision taken on a timeline step's plan (the journal's ``decision`` event)."""

    kind: str = Field(description="approve, override, step, auto")
    plan_id: str | None
    index: int | None = Field(description="the candidate taken (None for a custom pose)")
    best_index: int | None = Field(description="the planner's choice of that plan")
    custom: bool
    pose: PoseModel


class TimelineStepOut(BaseModel):
    """The session as it was after view ``view`` (rebuilt from its journal)."""

    view: int = Field(description="1-based view index")
    plan_id: str | None = Field(description="the plan made from this view (the one a decision answered)")
    best: BestView | None = Field(description="that plan's best view (the planner's choice)")
    approved: int | None = Field(description="the candidate the decision took (None: none yet, or a custom pose)")
    decision: TimelineDecisionOut | None
    voxels: dict[str, int] = Field(description="voxel counts by class after this view")
    points: int
    coverage: float | None
    move_frames: int = Field(default=0, description="frames kept from the move to this view (capture during moves)")
    n_candidates: int | None
    n_eligible: int | None
    terminated: str | None


class TimelineOut(BaseModel):
    """Every step of a session's timeline."""

    views: int
    steps: list[TimelineStepOut]


class TimelineRequest(BaseModel):
    """Which view of the timeline a viewer shows; ``null``: the session now."""

    model_config = ConfigDict(extra="forbid")
    view: Annotated[StrictInt, Field(ge=1)] | None


class ReachClassOut(BaseModel):
    """A class of the reach layer (reachable, or why not) and its colour."""

    class_: str = Field(alias="class", description="reachable, no_ik, joint_limit, collision, turn, reach, other")
    label: str
    color: list[int]
    count: int | None = Field(None, description="views of the drawn map in this class (legend only)")

    model_config = ConfigDict(populate_by_name=True, serialize_by_alias=True)


class SceneInfoOut(BaseModel):
    viewer: str
    session: str
    connected: bool
    layers: dict[str, bool]
    nodes: list[str]
    colormap: list[list[float]]
    score_range: list[float]
    colors: dict[str, list[float]]
    scale: str
    timeline: TimelineStepOut | None = Field(None, description="the timeline's step shown, None: the session now")
    reach_classes: list[ReachClassOut] = Field(
        default_factory=list, description="the reach layer's classes, in legend order (class, label, colour)"
    )
    reach: list[ReachClassOut] | None = Field(
        None, description="the reach layer's classes present with their numbers of views; None: not drawn (yet)"
    )


class ClientsOut(BaseModel):
    clients: int = Field(description="the viewer's clients whose camera moved")


class HealthOut(BaseModel):
    status: str


class ClassCreate(BaseModel):
    """A class: ``seats`` sessions, each a student's, scanning one object or a list (seat i the i-th, round robin)."""

    model_config = ConfigDict(extra="forbid")
    seats: StrictInt = Field(description="how many students (1 to server.max_class_seats)")
    model: str | list[Annotated[str, Field(max_length=200)]] | None = Field(
        default=None, description="a model name (GET /api/models) or a list of them; default: the server's"
    )
    planner: str = Field(default="projection", max_length=40, description="the view evaluator of every seat")
    guided: StrictBool = Field(default=False, description="every seat in guided mode (the page explains each step)")
    config: dict[str, Any] = Field(default_factory=dict, description="any subset of the planner config, every seat")


class ClassSeatOut(BaseModel):
    seat: int = Field(description="1-based seat number")
    session: str = Field(description="the seat's session id")
    model: str
    joined: bool = Field(description="a student took this seat")
    resets: int = Field(description="how often the teacher reset it")


class ClassOut(BaseModel):
    """A class as created: its id, the join code students type (or scan) and every seat's session."""

    id: str
    code: str
    join: str = Field(description="the join page's path: /join/CODE")
    planner: str
    models: list[str]
    guided: bool
    paused: bool
    live_limit: int = Field(description="sessions this server keeps live at once now (raised to hold the seats)")
    seats: list[ClassSeatOut]


class BoardSeatOut(ClassSeatOut):
    state: str = Field(description="the session's state, asleep (its memory freed; woken by its student) or gone")
    asleep: bool
    views: int
    coverage: float | None
    points: int
    picture: bool = Field(description="GET .../seats/{seat}/picture.png has a picture")


class BoardOut(BaseModel):
    """The class board's data: every seat's state, read without waking a sleeping seat."""

    id: str
    code: str
    join: str
    planner: str
    models: list[str]
    guided: bool
    paused: bool
    created: float
    live_limit: int
    live: int = Field(description="seats live in memory now")
    seats: list[BoardSeatOut]


class JoinRequest(BaseModel):
    model_config = ConfigDict(extra="forbid")
    code: str = Field(min_length=4, max_length=12, description="the join code on the teacher's screen")
    seat: StrictInt | None = Field(default=None, ge=1, description="rejoin this seat (default: the next free one)")


class JoinOut(BaseModel):
    class_id: str = Field(alias="class")
    seat: int
    session: str
    guided: bool
    url: str = Field(description="the page of the seat's session")

    model_config = ConfigDict(populate_by_name=True)


class PauseRequest(BaseModel):
    model_config = ConfigDict(extra="forbid")
    paused: StrictBool
