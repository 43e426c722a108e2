"""The planner's noise and range settings (``planner.config.NoiseConfig``, ``candidates.max_range``) and the
cell's first view for a configured camera: the cell knows its sensor, the planner sees only frames."""

from __future__ import annotations

import dataclasses
import math

from devices.calibration_error import calibration_named
from devices.config import CameraConfig, CellConfig
from devices.sensors.presets import sensor_named
from planner.config import CandidateConfig, NoiseConfig, PlannerConfig


def noise_config(camera: CameraConfig, base: NoiseConfig | None = None) -> NoiseConfig:
    """``base`` (default ``NoiseConfig()``) with the depth noise of ``camera``: its sensor's triangulation term
    (``subpixel / (focal_px * baseline)`` per z**2) and, range-independent, ``depth_noise_std`` and the depth
    unit's rounding (unit / sqrt(12)) in quadrature."""
    base = base if base is not None else NoiseConfig()
    sensor = sensor_named(camera.sensor)
    z2 = sensor.depth_rms(1.0)
    flat = math.sqrt(camera.depth_noise_std**2 + sensor.depth_unit**2 / 12.0)
    return dataclasses.replace(base, depth_std=flat, depth_z2=z2)


OBJECT_RADIUS = 0.15
"""How far from the turntable axis a plate-angle error is felt, metres (the development objects' half size)."""


def per_move_pose_error(camera: CameraConfig, distance: float) -> float:
    """Std of the pose error that changes from one view to the next, as a displacement at ``distance`` metres from
    the camera, metres: the arm's repeatability (translation, and rotation times ``distance``), the plate's angle
    error at ``OBJECT_RADIUS`` and the reported pose's own noise (``pose_noise_translation``), in quadrature. The
    fixed (bias) part of the calibration error is not in it: ICP, aligning frame to frame, cannot see a bias all
    frames share."""
    model = calibration_named(camera.calibration)
    return math.sqrt(
        model.arm_translation**2
        + (math.radians(model.arm_rotation_deg) * distance) ** 2
        + (math.radians(model.turntable_angle_deg) * OBJECT_RADIUS) ** 2
        + camera.pose_noise_translation**2
    )


def registration_resolves_nothing(camera: CameraConfig, working_distance: float) -> bool:
    """True when ICP should be off: the camera has depth noise and the per-move pose error
    (:func:`per_move_pose_error`) is smaller than the depth noise at the working distance plus B's typical
    half-diagonal (``working_distance + OBJECT_RADIUS``). Then ICP has nothing to correct that it can resolve, and
    what it does find is the noise: measured on D435 + typical, its corrections shifted the cloud by 2-3 mm
    (elephant: precision 0.867 with ICP, 0.997 without; recall 0.788 / 0.975). A perfect camera (no depth noise)
    keeps ICP, the paper's method."""
    sigma = noise_config(camera).depth_std
    distance = working_distance + OBJECT_RADIUS
    sigma = math.hypot(sigma, sensor_named(camera.sensor).depth_rms(distance))
    return sigma > 0 and per_move_pose_error(camera, distance) < sigma


DROPOUT_FILL_PX = 6
"""For a sensor that drops out (holes, the second viewpoint's shadow, grazing incidence): a pixel without depth within
this many pixels of a return is a dropout, free space only up to the nearest depth around it
(``NoiseConfig.dropout_fill_px``). Measured over the 17 development meshes (seed 0, typical calibration):
structured-light recall 0.910 -> 0.914; on the fertility (structured light, seed 0) the surface samples whose voxel
was carved EMPTY for good 1,346 -> 121 (docs/experiments/sensors.md, "Why do the D405 and structured light lose
recall?")."""

SUPPORT_MIN_POINTS = 5
"""For a sensor with flying pixels: a 1 cm cell with fewer of a frame's points is not surface
(``PreprocessConfig.support_min_points``)."""


LOW_ELEVATION_DEG = -5.0
"""For a sensor with a grazing limit: the candidate sphere's lowest parallel, degrees (the paper's cell: 10 above
the sphere's centre). A surface whose normal points beta below the horizon returns to a camera at elevation e only
when beta + e is within the limit (70-75 degrees against the perfect camera's 90), so the low parallels are where
such a sensor's downward and steep faces are measured. Measured over the 17 development meshes (seed 0, typical
calibration, with ``candidates.aim = "content"`` and the plate fit on horizontal points), recall@5mm for 10, 0, -5
and -10 degrees: D405 0.934, 0.943, 0.953, 0.957; structured light 0.916, 0.931, 0.939, 0.934 (docs/experiments/sensors.md,
"The sphere about the object and the low parallels"). The cell's reachability (the UR5, the plate, the table below it)
decides which of the low views can be taken."""

PLATE_FIT_MAX_TILT_DEG = 30.0
"""For a sensor with a grazing limit: the plate is fitted to points whose surface normal lies within this of the
vertical (``NoiseConfig.plate_fit_max_tilt_deg``). From the low parallels such a sensor sees the plate's rim but
not its top; fitted to the rim the plane lay up to 4 mm low, and the rim's top edge stayed in the cloud
(structured light with the low parallels, six meshes: precision 0.975 without, 0.9998 with)."""


def planner_config_for(config: PlannerConfig, camera: CameraConfig) -> PlannerConfig:
    """``config`` with its ``noise`` section set from ``camera`` (a perfect camera leaves it at 0; a calibration
    error turns ``fit_plate`` on), for a sensor with flying pixels the support filter on (``SUPPORT_MIN_POINTS``
    per voxel of the map) unless already set, and for a sensor with a finite range ``candidates.max_range`` set
    to it unless already set (the candidate sphere shrinks so B's far corner stays in range, and a ray without a
    return is free space only up to it) and the sphere built about the object seen (``candidates.aim =
    "content"``: B grown along the first view put the aim 10 cm off the object and, through the range rule, the
    D405's cameras 5 cm nearer, the object partly outside its images). A non-ideal sensor also gets dropout-aware
    carving (``DROPOUT_FILL_PX``) unless already set, and one with a grazing limit the low parallels (``LOW_ELEVATION_DEG``)
    unless the lowest elevation was changed, and the plate fit on horizontal points (``PLATE_FIT_MAX_TILT_DEG``)
    unless already set."""
    out = dataclasses.replace(config, noise=noise_config(camera, config.noise))
    sensor = sensor_named(camera.sensor)
    if math.isfinite(sensor.max_range) and config.candidates.max_range == 0:
        out = dataclasses.replace(out, candidates=dataclasses.replace(out.candidates, max_range=sensor.max_range))
    if math.isfinite(sensor.max_range) and config.candidates.aim == "bbox":
        out = dataclasses.replace(out, candidates=dataclasses.replace(out.candidates, aim="content"))
    grazing = sensor.max_incidence_deg < 90
    if grazing and config.candidates.min_elevation_deg == CandidateConfig().min_elevation_deg:
        out = dataclasses.replace(
            out, candidates=dataclasses.replace(out.candidates, min_elevation_deg=LOW_ELEVATION_DEG)
        )
    if grazing and config.noise.plate_fit_max_tilt_deg == 90:
        out = dataclasses.replace(
            out, noise=dataclasses.replace(out.noise, plate_fit_max_tilt_deg=PLATE_FIT_MAX_TILT_DEG)
        )
    if not sensor.is_ideal and config.noise.dropout_fill_px == 0:
        out = dataclasses.replace(out, noise=dataclasses.replace(out.noise, dropout_fill_px=DROPOUT_FILL_PX))
    if camera.calibration != "none":  # the plate seen through the reported pose is tilted and offset
        out = dataclasses.replace(out, noise=dataclasses.replace(out.noise, fit_plate=True))
    if registration_resolves_nothing(camera, out.candidates.working_distance):
        out = dataclasses.replace(out, registration=dataclasses.replace(out.registration, enabled=False))
    if sensor.flying_probability > 0 and config.preprocess.support_min_points == 0:
        pre = dataclasses.replace(
            config.preprocess, support_min_points=SUPPORT_MIN_POINTS, support_voxel=config.voxel.resolution
        )
        out = dataclasses.replace(out, preprocess=pre)
    return out


FIRST_VIEW_RANGE_FRACTION = 0.7
"""The first view is at most this share of the sensor's maximum range from its look-at point (the object spans
about +-0.15 m around it: a D405, 0.5 m, looks from 0.35 m, the paper's d_c, instead of the cell's 0.55 m)."""


def cell_config_for(cell: CellConfig, camera: CameraConfig) -> CellConfig:
    """``cell`` with its first view (``initial_distance``) brought within ``FIRST_VIEW_RANGE_FRACTION`` of the
    sensor's maximum range when it lies beyond: from 0.55 m a D405 (0.5 m) returns nothing of the object, and the
    scan cannot start. Sensors with range to spare (ideal, D435, structured light at 0.8 m) leave it alone."""
    limit = FIRST_VIEW_RANGE_FRACTION * sensor_named(camera.sensor).max_range
    if cell.initial_distance <= limit:
        return cell
    return dataclasses.replace(cell, initial_distance=limit)
