"""What every session worker forks with: imported by the forkserver once (``worker_context``'s preload), so a
worker starts with the heavy libraries imported and the default cell's arm loaded.

The default UR5 (``CellConfig()``) is loaded here: its URDF model (``load_arm``'s cache) and its IK seed library
(shared per process, ``devices/arm/reach.py``) come to each worker with the fork instead of being built again
by each (75 ms of CPU per session's worker). A cell with another arm builds its own, as before. Nothing here may
stop the forkserver: a failure is logged and the workers build what they need themselves.
"""

from __future__ import annotations

import gc
import logging

import open3d  # noqa: F401  (imported for the fork)
import pinocchio  # noqa: F401  # pyright: ignore[reportMissingImports]  (under cmeel.prefix)

import devices.sim  # noqa: F401
import planner.baselines  # noqa: F401  (the planners a worker may be asked for)
import workbench.sources.mesh_loader
import workbench.workers.child  # noqa: F401
from devices.arm.kinematics import ArmKinematics
from devices.config import CellConfig

log = logging.getLogger(__name__)


def _load_default_arm() -> None:
    cell = CellConfig()
    try:
        ArmKinematics(cell.arm, cell.plate_radius, cell.plate_thickness)
    except Exception as exc:  # a broken robot install: the worker that needs the arm reports it
        log.warning("worker preload: the default arm did not load: %s", exc)


_load_default_arm()
# Everything loaded so far moves to the collector's permanent generation: a worker's collections then never walk
# (and so never write to, copying the page of) the objects it shares with the forkserver. Measured per worker
# (setup and warm-up jobs, then a full collection): 0.25 -> 0.11 s of CPU, 18,700 -> 9,000 pages copied.
gc.freeze()
