"""nbv calibrate: the simulated cell's JSON, the rehearsal of a cell file's poses, one-line errors."""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from nbv.cli import main

CELL = """\
[devices]
[devices.camera]
driver = "sim"

[devices.hand_eye]
translation = [0.0, 0.0, 0.05]

[devices.arm_base]
translation = [-0.85, 0.0, 0.0]
"""


@pytest.mark.slow
@pytest.mark.timeout(300)
def test_sim_json_is_one_object_with_the_errors(capsys: pytest.CaptureFixture[str]) -> None:
    """Three plate angles (18 poses, half the default's captures): the default 36 are recovered within the bounds
    in tests/devices/test_calibration_sim.py and tests/workbench/test_calibration_run.py."""
    args = ["calibrate", "--sim", "--calibration", "poor", "--seed", "1", "--json", "--plate-angles", "0,120,240"]
    assert main(args) == 0
    out = capsys.readouterr().out.strip()
    assert out.count("\n") == 0  # one JSON object, nothing else on stdout
    data = json.loads(out)
    assert data["seed"] == 1 and data["calibration"] == "poor" and data["sensor"] == "realsense-d435"
    assert data["captures"] == 18 and data["skipped"] == []
    assert data["hand_eye_error_mm"] < 1.0 and data["hand_eye_error_deg"] < 0.2
    assert data["axis_error_mm"] < 1.0 and data["axis_error_deg"] < 0.2
    assert data["nominal_error"]["hand_eye_mm"] > 3 * data["hand_eye_error_mm"]
    assert len(data["true"]["T_flange_camera"]) == 4 and len(data["recovered"]["residuals_mm"]) == 18


@pytest.mark.timeout(300)
def test_dry_run_of_a_cell_file_rehearses_every_pose_and_writes_nothing(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    path = tmp_path / "cell.toml"
    path.write_text(CELL)
    assert main(["calibrate", "--cell", str(path), "--dry-run"]) == 0
    out = capsys.readouterr().out.splitlines()
    assert out[-1] == "dry run: 36 of 36 poses reachable; nothing was moved"
    assert sum("4 of 4 spheres in view" in line for line in out) >= 24
    assert path.read_text() == CELL and [p.name for p in tmp_path.iterdir()] == ["cell.toml"]


def test_bad_input_is_one_line(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["calibrate", "--sim", "--write"]) == 2
    assert "--write needs --cell" in capsys.readouterr().err
    assert main(["calibrate", "--cell", str(tmp_path / "nope.toml"), "--dry-run"]) == 2
    assert "cannot read the cell file" in capsys.readouterr().err
    assert main(["calibrate", "--sim", "--calibration", "awful", "--dry-run"]) == 2
    assert "unknown calibration 'awful'" in capsys.readouterr().err
