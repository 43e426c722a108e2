"""Preprocessing that follows the sensor's noise: the plate's scattered points do not become object and do not
grow B (the issue's first frame: 3,519 plate points kept at 2 mm noise, B grown to the plate)."""

from __future__ import annotations

import numpy as np
import pytest

from devices.builtins import make_builtin
from devices.config import CameraConfig, CellConfig
from devices.planner_noise import noise_config, planner_config_for
from devices.sensors import sensor_named
from devices.sim import make_sim_cell
from planner import Planner, PlannerConfig


def first_frame_planner(camera: CameraConfig, tuned: bool) -> Planner:
    cell = make_sim_cell(make_builtin("l-block"), camera, CellConfig(), seed=0)
    planner = Planner(planner_config_for(PlannerConfig(), camera) if tuned else PlannerConfig())
    planner.integrate(cell.capture())
    return planner


@pytest.fixture(scope="module")
def noiseless() -> Planner:
    return first_frame_planner(CameraConfig(), tuned=True)


def test_fixed_band_keeps_the_noisy_plate(noiseless: Planner) -> None:
    """The paper's fixed 2 mm band (the default NoiseConfig): at 2 mm noise, plate points become object."""
    noisy = first_frame_planner(CameraConfig(depth_noise_std=0.002), tuned=False)
    assert int(np.count_nonzero(noisy.cloud[:, 2] < 0.003)) > 500
    assert noiseless.voxel_map.bbox is not None and noisy.voxel_map.bbox is not None
    assert np.max(np.abs(noisy.voxel_map.bbox.upper - noiseless.voxel_map.bbox.upper)) > 0.05


@pytest.mark.parametrize(
    "camera",
    [
        CameraConfig(depth_noise_std=0.002),
        CameraConfig(sensor="realsense-d435"),
        CameraConfig(sensor="structured-light"),
    ],
)
def test_noise_band_removes_the_plate_and_keeps_B(noiseless: Planner, camera: CameraConfig) -> None:
    noisy = first_frame_planner(camera, tuned=True)
    lo, hi = make_builtin("l-block").bounds
    low = noisy.cloud[noisy.cloud[:, 2] < 0.003]
    off_object = np.any((low[:, :2] < lo[:2] - 0.003) | (low[:, :2] > hi[:2] + 0.003), axis=1)
    assert int(np.count_nonzero(off_object)) == 0  # low points are the object's foot, none is plate
    a, b = noiseless.voxel_map.bbox, noisy.voxel_map.bbox
    assert a is not None and b is not None
    # never larger than the perfect camera's B (a sensor that sees less, by range or occlusion, may grow it less)
    assert np.all(b.lower >= a.lower - 0.02) and np.all(b.upper <= a.upper + 0.02)
    if camera.sensor == "ideal":  # the check: depth noise alone, B within 2 cm of the noiseless one
        assert np.max(np.abs(a.lower - b.lower)) <= 0.02 and np.max(np.abs(a.upper - b.upper)) <= 0.02


def test_noise_config_of_a_camera() -> None:
    d435 = noise_config(CameraConfig(sensor="realsense-d435"))
    assert d435.depth_z2 == pytest.approx(sensor_named("realsense-d435").depth_rms(1.0))
    assert d435.depth_std == pytest.approx(0.001 / np.sqrt(12))  # the 1 mm depth unit's rounding
    assert noise_config(CameraConfig()).exact
    flat = noise_config(CameraConfig(depth_noise_std=0.002))
    assert flat.depth_std == pytest.approx(0.002) and flat.depth_z2 == 0


def test_one_plate_fit_per_frame_from_the_measured_depths(monkeypatch: pytest.MonkeyPatch) -> None:
    """With a D435 the planner carves a dropout-filled copy of the frame; its plate is the measured frame's plane
    (one fit a frame, on depths the sensor returned, none invented by the fill), not a second fit."""
    import planner.noise as noise_module

    camera = CameraConfig(sensor="realsense-d435", calibration="typical")
    cell = make_sim_cell(make_builtin("l-block"), camera, CellConfig(), seed=0)
    config = planner_config_for(PlannerConfig(), camera)
    assert config.noise.fit_plate and config.noise.dropout_fill_px > 0
    fits: list[int] = []
    fit = noise_module.fit_plate

    def counted(points_world: np.ndarray, *args: object, **kwargs: object) -> np.ndarray:
        fits.append(len(points_world))
        return fit(points_world, *args, **kwargs)  # type: ignore[arg-type]

    monkeypatch.setattr(noise_module, "fit_plate", counted)
    planner = Planner(config)
    frame = cell.capture()
    planner.integrate(frame)
    assert fits == [int(np.count_nonzero(frame.valid))]  # once, on the measured frame's points


def test_a_registered_frame_carves_its_plate_from_the_moved_plane(monkeypatch: pytest.MonkeyPatch) -> None:
    """Without dropout filling, a frame that registration moves is carved with plate heights of the moved frame
    against the moved plane: its plate pixels stay "no return" (free space down to the plate), however far the
    correction lifted them. Before, the heights were the frame's before the correction, so plate points lifted by
    a centimetre were carved as returns (the voxel layer on the plate left unknown)."""
    import planner.planner as planner_module
    from planner import Pose
    from planner.registration import RegistrationResult

    camera = CameraConfig(sensor="realsense-d435", calibration="typical")
    cell = make_sim_cell(make_builtin("l-block"), camera, CellConfig(), seed=0)
    base = planner_config_for(PlannerConfig(), camera)
    config = base.replace(noise={"dropout_fill_px": 0}, registration={"enabled": True})
    assert config.noise.fit_plate and config.registration.enabled
    lift = Pose(np.eye(3), np.array([0.0, 0.0, 0.01]))
    monkeypatch.setattr(
        planner_module,
        "register",
        lambda *args, **kwargs: RegistrationResult(lift, 1.0, 0.0, True, "ok: test", 0.01),
    )
    planner = Planner(config)
    planner.integrate(cell.capture())  # the first frame: nothing to register to
    carved: list[np.ndarray] = []
    integrate = planner.voxel_map.integrate

    def spy(frame, points):  # type: ignore[no-untyped-def]
        carved.append(frame.depth)
        return integrate(frame, points)

    monkeypatch.setattr(planner.voxel_map, "integrate", spy)
    frame = cell.capture()
    planner.integrate(frame)
    moved = frame.with_pose(lift @ frame.T_world_camera)
    on_plate = moved.points_world[:, 2] < 0.01 + 0.002  # the plate (z = 0) lifted by the correction, 2 mm band
    v, u = np.nonzero(moved.depth > 0)
    assert np.count_nonzero(on_plate) > 1000  # the frame sees plenty of plate
    kept = carved[0][v[on_plate], u[on_plate]]
    assert np.count_nonzero(kept) < 0.01 * len(kept)  # (with the heights from before the correction: 99 % kept)
