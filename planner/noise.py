"""What the sensor's depth noise means for the planner's thresholds (pure numpy).

A perfect sensor needs none of this (``NoiseConfig`` at its defaults leaves every threshold as the paper's). A
noisy one scatters the plate's points above its top: a fixed 2 mm band keeps a quarter of a 2 mm-noise frame as
"object", and B grows to the plate's extent. The band here follows the noise at each point's range, projected on
the vertical; ICP's rmse gate follows the noise at the frame's median range.
"""

from __future__ import annotations

import dataclasses
import math

import numpy as np
from numpy.typing import NDArray

from planner.config import NoiseConfig, PreprocessConfig, RegistrationConfig
from planner.types import DepthFrame


def depth_std(depth: NDArray[np.floating], noise: NoiseConfig) -> NDArray[np.float64]:
    """(N,) std of the depth error at planar depths ``depth`` (N,), metres."""
    z = np.asarray(depth, dtype=np.float64)
    return np.sqrt(noise.depth_std**2 + (noise.depth_z2 * z * z) ** 2)


def plate_heights(frame: DepthFrame, preprocess: PreprocessConfig, noise: NoiseConfig) -> NDArray[np.float64]:
    """(N,) per point of ``frame.points_world``: below this height above the plate top a point is plate.

    ``max(plate_clearance, plate_sigmas * sigma_z)``, where sigma_z is the depth std at the point's depth times
    the vertical component of its ray (a ray along the vertical moves the point up and down by its whole error,
    a grazing one hardly at all)."""
    n = int(np.count_nonzero(frame.valid))
    if noise.exact:
        return np.full(n, preprocess.plate_clearance)
    depth = frame.depth[frame.valid].astype(np.float64)
    points = frame.points_world
    vertical = np.abs(points[:, 2] - frame.T_world_camera.translation[2]) / np.maximum(depth, 1e-9)
    return np.maximum(preprocess.plate_clearance, noise.plate_sigmas * depth_std(depth, noise) * vertical)


def registration_for(frame: DepthFrame, config: RegistrationConfig, noise: NoiseConfig) -> RegistrationConfig:
    """``config`` with its rmse gate raised to ``icp_sigmas * sqrt(2) * sigma(median depth)`` when that is larger
    (two noisy clouds: the frame's and the accumulated one's), and the correspondence distance kept above three
    times the gate. A perfect sensor gets ``config`` unchanged."""
    if noise.exact or not np.any(frame.valid):
        return config
    sigma = float(depth_std(np.array([np.median(frame.depth[frame.valid])]), noise)[0])
    gate = noise.icp_sigmas * math.sqrt(2.0) * sigma
    if gate <= config.max_rmse:
        return config
    return dataclasses.replace(
        config, max_rmse=gate, max_correspondence=max(config.max_correspondence, 3.0 * gate)
    )
