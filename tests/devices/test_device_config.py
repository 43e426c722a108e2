"""CameraConfig, CellConfig, DeviceConfig: documented defaults and validation naming the field."""

from __future__ import annotations

import pytest

from devices.config import CameraConfig, CellConfig, DeviceConfig
from planner.config import from_dict
from planner.types import Intrinsics


def test_camera_defaults_and_intrinsics() -> None:
    c = CameraConfig()
    assert (c.width, c.height, c.fx, c.fy, c.cx, c.cy) == (640, 480, 610.0, 610.0, 319.5, 239.5)
    assert (c.min_depth, c.max_depth) == (0.1, 1.5)
    assert (c.depth_noise_std, c.pose_noise_translation, c.pose_noise_rotation_deg) == (0.0, 0.0, 0.0)
    assert c.intrinsics == Intrinsics(640, 480, 610.0, 610.0, 319.5, 239.5)
    assert CameraConfig(width=320, fx=300.0).intrinsics == Intrinsics(320, 480, 300.0, 610.0, 319.5, 239.5)


def test_cell_defaults() -> None:
    c = CellConfig()
    assert c.arm_base == (-0.45, 0.0, 0.0)
    assert (c.arm_reach, c.arm_min_reach, c.min_height) == (0.8, 0.15, 0.01)
    assert (c.plate_radius, c.plate_thickness) == (0.2, 0.02)
    assert (c.initial_elevation_deg, c.initial_azimuth_deg, c.initial_distance, c.initial_target_height) == (
        30.0,
        180.0,
        0.55,
        0.1,
    )


@pytest.mark.parametrize(
    ("kwargs", "field"),
    [
        ({"width": 0}, "camera.width"),
        ({"height": 2.5}, "camera.height"),
        ({"fx": -1.0}, "camera.fx"),
        ({"fy": float("nan")}, "camera.fy"),
        ({"cx": float("inf")}, "camera.cx"),
        ({"min_depth": -0.1}, "camera.min_depth"),
        ({"max_depth": 0.05}, "camera.max_depth"),
        ({"depth_noise_std": -0.001}, "camera.depth_noise_std"),
        ({"pose_noise_translation": float("nan")}, "camera.pose_noise_translation"),
        ({"pose_noise_rotation_deg": -1.0}, "camera.pose_noise_rotation_deg"),
    ],
)
def test_camera_validation_names_the_field(kwargs: dict, field: str) -> None:
    with pytest.raises(ValueError, match=f"^{field}:"):
        CameraConfig(**kwargs)


@pytest.mark.parametrize(
    ("kwargs", "field"),
    [
        ({"arm_base": (0.0, 0.0)}, "cell.arm_base"),
        ({"arm_base": ("a", 0.0, 0.0)}, "cell.arm_base"),
        ({"arm_base": (0.0, float("nan"), 0.0)}, "cell.arm_base"),
        ({"arm_reach": 0.1}, "cell.arm_reach"),
        ({"arm_min_reach": -0.1}, "cell.arm_min_reach"),
        ({"min_height": -0.01}, "cell.min_height"),
        ({"plate_radius": 0.0}, "cell.plate_radius"),
        ({"plate_thickness": -0.02}, "cell.plate_thickness"),
        ({"initial_distance": 0.0}, "cell.initial_distance"),
        ({"initial_elevation_deg": -90.0}, "cell.initial_elevation_deg"),
        ({"initial_azimuth_deg": float("inf")}, "cell.initial_azimuth_deg"),
        ({"initial_target_height": float("nan")}, "cell.initial_target_height"),
    ],
)
def test_cell_validation_names_the_field(kwargs: dict, field: str) -> None:
    with pytest.raises(ValueError, match=f"^{field}:"):
        CellConfig(**kwargs)


def test_arm_base_list_becomes_tuple() -> None:
    assert CellConfig(arm_base=[-0.5, 0.1, 0.05]).arm_base == (-0.5, 0.1, 0.05)  # type: ignore[arg-type]


@pytest.mark.parametrize(
    ("kwargs", "field"),
    [
        ({"model": ""}, "devices.model"),
        ({"size": 0.0}, "devices.size"),
        ({"up": "x"}, "devices.up"),
        ({"seed": -1}, "devices.seed"),
        ({"camera": "nope"}, "devices.camera"),
    ],
)
def test_device_validation_names_the_field(kwargs: dict, field: str) -> None:
    with pytest.raises(ValueError, match=f"^{field}:"):
        DeviceConfig(**kwargs)


def test_device_config_from_nested_dict() -> None:
    cfg = from_dict(
        DeviceConfig,
        {"camera": {"depth_noise_std": 0.001}, "cell": {"arm_base": [-0.5, 0.0, 0.1]}, "model": "mug", "up": "z"},
    )
    assert cfg.camera.depth_noise_std == 0.001
    assert cfg.camera.width == 640
    assert cfg.cell.arm_base == (-0.5, 0.0, 0.1)
    assert (cfg.model, cfg.up, cfg.size, cfg.seed) == ("mug", "z", 0.2, 0)
    with pytest.raises(ValueError, match=r"camera\.fx"):
        from_dict(DeviceConfig, {"camera": {"fx": -3.0}})
