"""Supervised scanning, independent of HTTP and of the 3D scene.

A session (:class:`Session`) owns a planner, a cell and a lock; every state change of a scan goes through
it (workbench/session/). The registry (:class:`SessionRegistry`, workbench/registry/) holds the live ones
and the journaled ones of an earlier server. Importing this package loads no fastapi, uvicorn or viser.

These names are the public API the web layer (app/), the command line (nbv/) and the benchmarks use;
``workbench.evaluation`` and ``workbench.journal`` list their own. docs/architecture.md shows the tree.
"""

from workbench.calibration import CalibrationRun, Calibrations, PosePreview
from workbench.classes import Classes, ClassRoom
from workbench.errors import (
    AtCapacity,
    Conflict,
    DeviceFault,
    Gone,
    Interrupted,
    Invalid,
    NotFound,
    StorageFault,
    TooLarge,
    Unreachable,
    WorkbenchError,
)
from workbench.journal.timeline import TimelineStep, timeline_of
from workbench.jsonable import jsonable
from workbench.progress import Progress
from workbench.registry.creations import resume_id
from workbench.registry.registry import SessionRegistry
from workbench.session.fit import Refit
from workbench.session.session import Session
from workbench.session.states import BUSY, Listed, State
from workbench.session.summaries import SessionStatus, best_of, plan_summary
from workbench.session.values import SceneData, SessionEvent
from workbench.settings import WorkbenchSettings
from workbench.sources.camera_models import camera_models
from workbench.sources.catalog import list_models, load_model, save_upload
from workbench.sources.parts import arm_choices, list_recorded, list_recordings

__all__ = [
    "BUSY",
    "AtCapacity",
    "CalibrationRun",
    "Calibrations",
    "ClassRoom",
    "Classes",
    "Conflict",
    "DeviceFault",
    "Gone",
    "Interrupted",
    "Invalid",
    "Listed",
    "NotFound",
    "PosePreview",
    "Progress",
    "Refit",
    "SceneData",
    "Session",
    "SessionEvent",
    "SessionRegistry",
    "SessionStatus",
    "State",
    "StorageFault",
    "TimelineStep",
    "TooLarge",
    "Unreachable",
    "WorkbenchError",
    "WorkbenchSettings",
    "arm_choices",
    "best_of",
    "camera_models",
    "jsonable",
    "list_models",
    "list_recorded",
    "list_recordings",
    "load_model",
    "plan_summary",
    "resume_id",
    "save_upload",
    "timeline_of",
]
