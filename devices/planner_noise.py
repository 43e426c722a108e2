"""The planner's noise settings (``planner.config.NoiseConfig``) for a configured camera: the cell knows its
sensor, the planner sees only frames."""

from __future__ import annotations

import dataclasses
import math

from devices.config import CameraConfig
from devices.sensors.presets import sensor_named
from planner.config import NoiseConfig, PlannerConfig


def noise_config(camera: CameraConfig, base: NoiseConfig | None = None) -> NoiseConfig:
    """``base`` (default ``NoiseConfig()``) with the depth noise of ``camera``: its sensor's triangulation term
    (``subpixel / (focal_px * baseline)`` per z**2) and, range-independent, ``depth_noise_std`` and the depth
    unit's rounding (unit / sqrt(12)) in quadrature."""
    base = base if base is not None else NoiseConfig()
    sensor = sensor_named(camera.sensor)
    z2 = sensor.depth_rms(1.0)
    flat = math.sqrt(camera.depth_noise_std**2 + sensor.depth_unit**2 / 12.0)
    return dataclasses.replace(base, depth_std=flat, depth_z2=z2)


SUPPORT_MIN_POINTS = 5
"""For a sensor with flying pixels: a 1 cm cell with fewer of a frame's points is not surface
(``PreprocessConfig.support_min_points``)."""


def planner_config_for(config: PlannerConfig, camera: CameraConfig) -> PlannerConfig:
    """``config`` with its ``noise`` section set from ``camera`` (a perfect camera leaves it at 0; a calibration
    error turns ``fit_plate`` on) and, for a sensor
    with flying pixels, the support filter on (``SUPPORT_MIN_POINTS`` per voxel of the map) unless already set."""
    out = dataclasses.replace(config, noise=noise_config(camera, config.noise))
    if camera.calibration != "none":  # the plate seen through the reported pose is tilted and offset
        out = dataclasses.replace(out, noise=dataclasses.replace(out.noise, fit_plate=True))
    if sensor_named(camera.sensor).flying_probability > 0 and config.preprocess.support_min_points == 0:
        pre = dataclasses.replace(
            config.preprocess, support_min_points=SUPPORT_MIN_POINTS, support_voxel=config.voxel.resolution
        )
        out = dataclasses.replace(out, preprocess=pre)
    return out
