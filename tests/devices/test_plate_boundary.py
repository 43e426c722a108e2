"""The plate top (z = 0) lies on a voxel boundary: a sub-millimetre change of the depth must not flip the map's
classes there (the plate band removes the plate's points and carves their rays before any voxel sees them)."""

from __future__ import annotations

import numpy as np
import pytest
import trimesh

from devices.config import CameraConfig, CellConfig
from devices.sim import make_sim_cell
from planner import Planner, PlannerConfig
from planner.types import DepthFrame, VoxelClass


@pytest.mark.parametrize("dz", [0.00005, -0.00005, 0.0003])
def test_a_sub_millimetre_depth_change_does_not_flip_the_map(dz: float) -> None:
    sphere = trimesh.creation.icosphere(subdivisions=3, radius=0.07)
    sphere.apply_translation((0.013, -0.007, 0.07))  # resting on the plate, off the lattice's symmetry
    cell = make_sim_cell(sphere, CameraConfig(), CellConfig(kinematics="reach_sphere"), seed=0)
    frame = cell.capture()
    counts = []
    for shift in (0.0, dz):
        depth = np.where(frame.depth > 0, frame.depth + np.float32(shift), 0).astype(np.float32)
        planner = Planner(PlannerConfig())
        planner.integrate(DepthFrame(depth, frame.T_world_camera, frame.intrinsics))
        counts.append({c: planner.voxel_map.count(c) for c in VoxelClass})
    base, moved = counts
    assert abs(moved[VoxelClass.OCCUPIED] - base[VoxelClass.OCCUPIED]) <= 0.03 * base[VoxelClass.OCCUPIED]
    assert abs(moved[VoxelClass.FRONTIER] - base[VoxelClass.FRONTIER]) <= 0.05 * base[VoxelClass.FRONTIER] + 3
