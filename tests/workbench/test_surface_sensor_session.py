"""A session's surface fuses with its camera's settings (``surface_config_for``, as ``nbv scan`` and ``nbv bench``
do): a real sensor's noise with the tighter truncation; the journal's header carries the camera, so a resume
rebuilds the same surface."""

from __future__ import annotations

import dataclasses
from pathlib import Path

import numpy as np
import pytest

from devices.config import CameraConfig, DeviceConfig
from tests.helpers import SMALL
from workbench.journal.store import read_journal, sessions_dir
from workbench.journal.surface import header_surface_config, surface_of_journal
from workbench.registry.registry import SessionRegistry
from workbench.settings import WorkbenchSettings
from workbench.surface.config import REAL_SENSOR_TRUNCATION_VOXELS, SurfaceConfig

SMALL_CAMERA = CameraConfig(width=160, height=120, fx=152.5, fy=152.5, cx=79.5, cy=59.5)


def test_the_header_gives_the_cameras_surface_settings() -> None:
    ideal = {"devices": dataclasses.asdict(DeviceConfig())}
    d435 = {"devices": dataclasses.asdict(DeviceConfig(camera=CameraConfig(sensor="realsense-d435")))}
    noisy = {"devices": dataclasses.asdict(DeviceConfig(camera=CameraConfig(depth_noise_std=0.002)))}
    assert header_surface_config(ideal) == SurfaceConfig()
    assert header_surface_config(d435).truncation_voxels == REAL_SENSOR_TRUNCATION_VOXELS
    assert header_surface_config(noisy).truncation_voxels == REAL_SENSOR_TRUNCATION_VOXELS
    assert SurfaceConfig().truncation_voxels != REAL_SENSOR_TRUNCATION_VOXELS
    assert header_surface_config({}) == SurfaceConfig()  # a header without devices: the defaults
    assert header_surface_config({"devices": {"camera": {"sensor": 3}}}) == SurfaceConfig()


@pytest.mark.parametrize("sensor", ["ideal", "realsense-d435"])
def test_a_sessions_surface_follows_its_sensor_and_rebuilds_equal(tmp_path: Path, sensor: str) -> None:
    settings = WorkbenchSettings(
        models_dir=tmp_path / "models",
        data_dir=tmp_path / "data",
        workers=False,  # the surface lives in this process: its settings can be read
        devices=DeviceConfig(camera=SMALL_CAMERA),
    )
    registry = SessionRegistry(settings)
    try:
        session = registry.create(model="box", config=SMALL, camera={"sensor": sensor})
        session.capture()
        live = session.step_runner._surface
        assert live is not None and live.update is not None and live.update.mesh is not None
        expected = REAL_SENSOR_TRUNCATION_VOXELS if sensor != "ideal" else SurfaceConfig().truncation_voxels
        assert live.integrator.config.truncation_voxels == expected
        rebuilt = surface_of_journal(read_journal(sessions_dir(settings.data_dir) / session.id))
        assert rebuilt.integrator.config == live.integrator.config
        assert rebuilt.update is not None and rebuilt.update.mesh is not None
        np.testing.assert_array_equal(rebuilt.update.mesh.vertices, live.update.mesh.vertices)
        np.testing.assert_array_equal(rebuilt.update.mesh.faces, live.update.mesh.faces)
    finally:
        registry.close()
