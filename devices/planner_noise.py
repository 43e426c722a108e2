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


def planner_config_for(config: PlannerConfig, camera: CameraConfig) -> PlannerConfig:
    """``config`` with its ``noise`` section set from ``camera`` (a perfect camera leaves it at 0)."""
    return dataclasses.replace(config, noise=noise_config(camera, config.noise))
