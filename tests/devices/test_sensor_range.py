"""A sensor's range sets the planner's candidate sphere and the cell's first view: a D405 (0.5 m) from the
cell's 0.55 m first view returned nothing of the object and the scan could not start."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from devices.builtins import make_builtin
from devices.config import CameraConfig, CellConfig
from devices.planner_noise import (
    cell_config_for,
    per_move_pose_error,
    planner_config_for,
    registration_resolves_nothing,
)
from devices.sim import make_sim_cell
from planner import Planner, PlannerConfig


@pytest.mark.parametrize(
    ("sensor", "max_range", "first_view"),
    [
        ("ideal", 0.0, 0.55),
        ("realsense-d435", 3.0, 0.55),
        ("structured-light", 0.8, 0.55),
        ("realsense-d405", 0.5, 0.35),
    ],
)
def test_range_follows_the_sensor(sensor: str, max_range: float, first_view: float) -> None:
    camera = CameraConfig(sensor=sensor)
    assert planner_config_for(PlannerConfig(), camera).candidates.max_range == max_range
    assert cell_config_for(CellConfig(), camera).initial_distance == pytest.approx(first_view)
    assert cell_config_for(CellConfig(), CameraConfig()) == CellConfig()  # the ideal camera: the cell as given


def test_an_explicit_range_is_kept() -> None:
    config = PlannerConfig().replace(candidates={"max_range": 0.4})
    assert planner_config_for(config, CameraConfig(sensor="realsense-d405")).candidates.max_range == 0.4
    near = dataclasses.replace(CellConfig(), initial_distance=0.3)
    assert cell_config_for(near, CameraConfig(sensor="realsense-d405")) == near


def test_d405_first_frame_sees_the_object() -> None:
    """The D405's first view, brought within its range by the cell, has returns on the object; the planner
    takes it."""
    camera = CameraConfig(sensor="realsense-d405")
    cell = make_sim_cell(make_builtin("sphere"), camera, CellConfig(), seed=0)
    frame = cell.capture()
    points = frame.points_world
    on_object = points[points[:, 2] > 0.01]
    assert len(on_object) > 1000
    planner = Planner(planner_config_for(PlannerConfig(), camera))
    planner.integrate(frame)
    assert planner.voxel_map.bbox is not None and len(planner.cloud) > 100
    eye = cell.initial_pose().translation
    assert float(np.linalg.norm(eye - np.array([0.0, 0.0, 0.1]))) == pytest.approx(0.35)


@pytest.mark.parametrize(
    ("camera", "icp"),
    [
        (CameraConfig(), True),  # the paper's method
        (CameraConfig(calibration="poor"), True),  # a perfect depth: ICP resolves the arm's error
        (CameraConfig(sensor="realsense-d435", calibration="typical"), False),
        (CameraConfig(sensor="realsense-d435", calibration="poor"), False),  # 0.4 mm per move < 1.3 mm noise
        (CameraConfig(sensor="structured-light", calibration="typical"), False),
        (CameraConfig(sensor="structured-light", calibration="poor"), True),  # 0.4 mm > 0.13 mm noise
        (CameraConfig(depth_noise_std=0.002), False),
        (CameraConfig(depth_noise_std=0.002, pose_noise_translation=0.002), True),
    ],
)
def test_icp_only_where_the_pose_error_exceeds_the_noise(camera: CameraConfig, icp: bool) -> None:
    assert planner_config_for(PlannerConfig(), camera).registration.enabled is icp
    assert registration_resolves_nothing(camera, 0.35) is not icp
    assert per_move_pose_error(CameraConfig(calibration="typical"), 0.5) == pytest.approx(6.7e-5, rel=0.05)


@pytest.mark.parametrize(
    ("sensor", "fill"), [("ideal", 0), ("realsense-d435", 6), ("realsense-d405", 6), ("structured-light", 6)]
)
def test_dropouts_follow_the_sensor(sensor: str, fill: int) -> None:
    """A real sensor's dropouts carve only up to the depth around them; the ideal camera keeps the paper's planner
    exactly; a value set explicitly is kept."""
    config = planner_config_for(PlannerConfig(), CameraConfig(sensor=sensor))
    assert config.noise.dropout_fill_px == fill
    if sensor == "ideal":
        assert config == PlannerConfig()
    own = PlannerConfig().replace(noise={"dropout_fill_px": 2})
    kept = planner_config_for(own, CameraConfig(sensor=sensor))
    assert kept.noise.dropout_fill_px == 2


@pytest.mark.parametrize(
    ("sensor", "aim", "elevation", "tilt"),
    [
        ("ideal", "bbox", 10.0, 90.0),
        ("realsense-d435", "content", -5.0, 30.0),
        ("realsense-d405", "content", -5.0, 30.0),
        ("structured-light", "content", -5.0, 30.0),
    ],
)
def test_candidates_follow_the_sensor(sensor: str, aim: str, elevation: float, tilt: float) -> None:
    """A sensor with a finite range gets the sphere about the object seen, one with a grazing limit the low
    parallels and the plate fitted on horizontal points; the perfect camera keeps the paper's sphere; values set
    explicitly are kept."""
    config = planner_config_for(PlannerConfig(), CameraConfig(sensor=sensor, calibration="typical"))
    assert (config.candidates.aim, config.candidates.min_elevation_deg) == (aim, elevation)
    assert config.noise.plate_fit_max_tilt_deg == tilt
    own = PlannerConfig().replace(candidates={"min_elevation_deg": 20.0}, noise={"plate_fit_max_tilt_deg": 45.0})
    kept = planner_config_for(own, CameraConfig(sensor=sensor, calibration="typical"))
    assert (kept.candidates.min_elevation_deg, kept.noise.plate_fit_max_tilt_deg) == (20.0, 45.0)
