"""Settings from TOML and flags; the ``nbv serve`` options; the scene's pure geometry helpers."""

from __future__ import annotations

import argparse
from pathlib import Path

import numpy as np
import pytest

from app.scene.geometry import VIRIDIS, box_segments, candidate_colors, colormap, gmm_instance, sector_segments
from app.settings import AppSettings, load_settings
from nbv import serve
from planner import BoundingBox, Ellipsoid, Pose


def test_toml_and_overrides(tmp_path: Path) -> None:
    path = tmp_path / "wb.toml"
    path.write_text(
        '[server]\nport = 9001\nhost = "0.0.0.0"\nmodels_dir = "meshes"\n'
        "[planner]\nvoxel = { resolution = 0.02 }\n"
        '[devices]\nmodel = "mug"\ncamera = { depth_noise_std = 0.001 }\n'
    )
    s = load_settings(path, port=9002)
    assert (s.port, s.host, s.viser_host, s.models_dir) == (9002, "0.0.0.0", "0.0.0.0", Path("meshes"))
    assert s.planner.voxel.resolution == 0.02 and s.planner.candidates.count == 400
    assert s.devices.model == "mug" and s.devices.camera.depth_noise_std == 0.001
    assert load_settings(path, model="sphere").devices.model == "sphere"


@pytest.mark.parametrize(
    ("text", "message"),
    [
        ("[sever]\nport = 1\n", "unknown table"),
        ("[server]\nprt = 1\n", "unknown setting"),
        ("[server]\nport = 70000\n", "server.port"),
        ("[planner]\nvoxel = { resolution = -1 }\n", "resolution"),
        ("[devices]\ncamera = { fx = 0 }\n", "camera.fx"),
        ("[server\n", "invalid TOML"),
    ],
)
def test_bad_settings_name_the_problem(tmp_path: Path, text: str, message: str) -> None:
    path = tmp_path / "bad.toml"
    path.write_text(text)
    with pytest.raises(ValueError, match=message):
        load_settings(path)


def test_serve_arguments() -> None:
    parser = argparse.ArgumentParser()
    serve.add_arguments(parser)
    args = parser.parse_args(["--port", "8100", "--viser-port", "8190", "--model", "box", "--data-dir", "/tmp/x"])
    s = serve.settings_from_args(args)
    assert (s.host, s.port, s.viser_port, s.devices.model, s.data_dir) == (
        "127.0.0.1",
        8100,
        8190,
        "box",
        Path("/tmp/x"),
    )
    assert AppSettings().host == "127.0.0.1"


def test_serve_sensor_and_calibration_set_the_default_of_new_sessions(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    parser = argparse.ArgumentParser()
    serve.add_arguments(parser)
    s = serve.settings_from_args(parser.parse_args(["--sensor", "realsense-d435", "--calibration", "typical"]))
    assert (s.devices.camera.sensor, s.devices.camera.calibration) == ("realsense-d435", "typical")
    plain = serve.settings_from_args(parser.parse_args([]))
    assert (plain.devices.camera.sensor, plain.devices.camera.calibration) == ("ideal", "none")
    path = tmp_path / "wb.toml"
    path.write_text('[devices]\ncamera = { sensor = "structured-light" }\n')
    s = serve.settings_from_args(parser.parse_args(["--config", str(path), "--calibration", "poor"]))
    assert (s.devices.camera.sensor, s.devices.camera.calibration) == ("structured-light", "poor")  # flags win
    with pytest.raises(SystemExit):
        parser.parse_args(["--sensor", "kinect"])
    assert "realsense-d435" in capsys.readouterr().err  # the error lists the names


def test_colormap_and_candidate_colors() -> None:
    c = colormap(np.array([0.0, 0.5, 1.0]))
    assert c[0].tolist() == list(VIRIDIS[0]) and c[2].tolist() == list(VIRIDIS[-1])
    colors, lo, hi = candidate_colors([5.0, -2.0, 100.0], [True, True, False])
    assert np.allclose((lo, hi), np.percentile([5.0, -2.0], [5, 95]))  # percentiles of the eligible scores
    assert colors[0].tolist() == list(VIRIDIS[-1]) and colors[1].tolist() == list(VIRIDIS[0])
    assert colors[2].tolist() == [175, 175, 175]
    # one outlier does not flatten the rest: 99 scores spread over the scale, one far above
    scores = [float(k) for k in range(99)] + [1e6]
    colors, lo, hi = candidate_colors(scores, [True] * 100)
    assert hi < 100 and len({tuple(c) for c in colors[:99].tolist()}) >= 60


def test_box_and_sector_segments() -> None:
    segs = box_segments(BoundingBox(np.zeros(3), np.array([1.0, 2.0, 3.0])))
    lengths = sorted(np.linalg.norm(segs[:, 1] - segs[:, 0], axis=1).round(9).tolist())
    assert lengths == [1.0] * 4 + [2.0] * 4 + [3.0] * 4
    s = sector_segments(np.array([0.1, 0.0, 0.2]), 0.5, np.array([0.0, np.pi / 2]))
    assert np.allclose(s[0], [[0.1, 0, 0], [0.6, 0, 0]]) and np.allclose(s[1], [[0.1, 0, 0], [0.1, 0.5, 0]])


def test_gmm_instance_is_the_two_sigma_ellipsoid() -> None:
    cov = np.diag([0.01, 0.04, 0.09])
    e = Ellipsoid(np.zeros(3), np.ones(3), np.eye(3), "occupied", 10, np.array([1.0, 2.0, 3.0]), cov)
    wxyz, pos, axes = gmm_instance(e)  # type: ignore[misc]
    assert np.allclose(sorted(axes), [0.2, 0.4, 0.6]) and np.allclose(pos, [1, 2, 3])
    R = Pose.from_wxyz(wxyz, pos).rotation
    assert np.allclose((R * axes**2) @ R.T, 4.0 * cov)  # the 2-sigma ellipsoid of the covariance
    assert gmm_instance(Ellipsoid(np.zeros(3), np.ones(3), np.eye(3), "frontier")) is None


def test_reliability_and_security_settings_from_toml(tmp_path: Path) -> None:
    path = tmp_path / "wb.toml"
    path.write_text(
        '[server]\ntoken = "a-long-enough-token"\ncors_origins = ["https://lab.example/"]\n'
        "capture_timeout = 2.5\nmove_timeout = 0\nfault_api = true\n"
        '[faults]\ncapture_failure = 0.1\nschedule = [{ kind = "arm_halfway", at = 3 }]\n'
    )
    s = load_settings(path)
    assert (s.token, s.cors_origins, s.capture_timeout, s.move_timeout, s.fault_api) == (
        "a-long-enough-token",
        ("https://lab.example",),
        2.5,
        0,
        True,
    )
    assert s.faults.capture_failure == 0.1 and s.faults.schedule[0].kind == "arm_halfway"
    assert s.faults.schedule[0].at == 3


@pytest.mark.parametrize(
    ("text", "message"),
    [
        ("[server]\ncapture_timeout = -1\n", "server.capture_timeout"),
        ('[server]\ncors_origins = "https://x"\n', "server.cors_origins"),
        ('[server]\ntoken = "short"\n', "server.token"),
        ("[server]\nmax_body_bytes = 0\n", "server.max_body_bytes"),
        ("[faults]\narm_halfway = 3\n", "faults.arm_halfway"),
        ("[faults]\nschedule = [{ kind = 'x', at = 1 }]\n", "faults.schedule.kind"),
    ],
)
def test_bad_reliability_settings_name_the_problem(tmp_path: Path, text: str, message: str) -> None:
    path = tmp_path / "bad.toml"
    path.write_text(text)
    with pytest.raises(ValueError, match=message):
        load_settings(path)


def test_an_arm_that_cannot_load_stops_the_server_at_start_in_one_line(tmp_path) -> None:
    import subprocess
    import sys

    config = tmp_path / "cell.toml"
    config.write_text('[devices.cell.arm]\nurdf = "/nonexistent/robot.urdf"\n')
    out = subprocess.run(
        [sys.executable, "-m", "nbv.cli", "serve", "--config", str(config), "--port", "0"],
        capture_output=True,
        text=True,
        timeout=120,
    )
    assert out.returncode == 2
    assert out.stderr.strip() == "nbv: error: arm.urdf: no such file '/nonexistent/robot.urdf'"
