"""benchmarks/search_agreement.py: fast and exhaustive scans per placement, compared by their means."""

from __future__ import annotations

import json
import statistics
import subprocess
import sys
from pathlib import Path

import pytest
import trimesh

ROOT = Path(__file__).resolve().parents[2]
pytestmark = pytest.mark.slow  # four scans: tests/conftest.py hands the long groups out first

SMALL = "[voxel]\nresolution = 0.02\n[candidates]\ncount = 60\n[cluster]\nt_min = 2\nt_max = 4\n"


def test_agreement_table_matches_the_scans_it_ran(tmp_path: Path) -> None:
    models = tmp_path / "models"
    models.mkdir()
    # an L of two boxes, y-up like the Stanford files, saved under a name the script knows
    arm = trimesh.creation.box(extents=(0.3, 0.1, 0.1))
    post = trimesh.creation.box(extents=(0.1, 0.3, 0.1))
    post.apply_translation((-0.1, 0.1, 0.0))
    trimesh.util.concatenate([arm, post]).export(models / "bunny.obj")
    out = tmp_path / "agreement"
    config = tmp_path / "small.toml"
    config.write_text(SMALL)
    cmd = [
        sys.executable, str(ROOT / "benchmarks" / "search_agreement.py"), "--models", str(models), "--out", str(out),
        "--only", "bunny.obj", "--yaws", "0,90", "--views", "2", "--config", str(config), "--jobs", "1",
    ]  # fmt: skip
    proc = subprocess.run(cmd, capture_output=True, text=True, cwd=ROOT, timeout=600)
    assert proc.returncode in (0, 1), proc.stderr
    summary = json.loads((out / "agreement.json").read_text())["bunny.obj"]
    for search in ("fast", "exhaustive"):
        runs = [json.loads((out / "bunny" / f"yaw{yaw}" / search / "run.json").read_text()) for yaw in ("0", "90")]
        finals = [run["final_coverage"] for run in runs]
        assert summary[search] == finals
        assert all(0.05 < c <= 1.0 for c in finals)
        assert [run["yaw"] for run in runs] == [0.0, 90.0] and all(run["views"] == 2 for run in runs)
        assert all(run["model"] == "bunny.obj" and run["search"] == search for run in runs)
        for run in runs:  # the scan ran with this search and the config file's settings
            assert run["config"]["cluster"]["search"] == search and run["config"]["cluster"]["t_max"] == 4
            assert run["config"]["voxel"]["resolution"] == 0.02 and run["config"]["candidates"]["count"] == 60
    mean_diff = statistics.mean(summary["fast"]) - statistics.mean(summary["exhaustive"])
    assert abs(summary["mean_diff"] - mean_diff) < 1e-12
    assert summary["within_limit"] == (abs(mean_diff) <= 0.01)
    assert proc.returncode == (0 if summary["within_limit"] else 1)
    assert "within 1 point" in proc.stdout and "bunny.obj" in proc.stdout
