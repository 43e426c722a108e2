"""Depth images rendered by the simulated camera, recorded with librealsense's software device."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import trimesh
from numpy.typing import NDArray

from devices.config import CameraConfig
from devices.drivers.rsrecord import write_depth_recording
from devices.sim import SimulatedCamera
from planner.types import Intrinsics, Pose

# A small camera keeps the recordings small: 80 x 60 pixels, off-centre principal point, fx != fy.
SMALL = CameraConfig(width=80, height=60, fx=70.0, fy=72.0, cx=39.0, cy=30.5, min_depth=0.05, max_depth=3.0)
DEPTH_UNIT = 1e-4


def rendered_views(n: int = 3, camera: CameraConfig = SMALL) -> tuple[list[NDArray[np.float32]], Intrinsics]:
    """``n`` depth images of a 0.1 m box on the plate from cameras around it, and their intrinsics."""
    box = trimesh.creation.box(extents=(0.1, 0.08, 0.12))
    box.apply_translation((0.0, 0.0, 0.06))
    sim = SimulatedCamera(box, camera, plate_radius=0.2)
    depths = []
    for i in range(n):
        a = 2 * np.pi * i / n
        eye = (0.45 * np.cos(a), 0.45 * np.sin(a), 0.3)
        depths.append(sim.render(Pose.look_at(eye, (0.0, 0.0, 0.06))))
    return depths, camera.intrinsics


def record_views(folder: Path, n: int = 3) -> tuple[Path, list[NDArray[np.float32]], Intrinsics]:
    """(recording path, the rendered depths, intrinsics): ``n`` rendered views written to ``folder/scan.db3``."""
    depths, k = rendered_views(n)
    path = write_depth_recording(folder / "scan.db3", depths, k, depth_unit=DEPTH_UNIT)
    return path, depths, k
