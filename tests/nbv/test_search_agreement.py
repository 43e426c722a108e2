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
pytestmark = pytest.mark.slow  # five Python processes: tests/conftest.py hands the long groups out first

SMALL = "--resolution 0.02 --candidates 60 --t-min 2 --t-max 4"


def test_agreement_table_matches_the_scans_it_ran(tmp_path: Path) -> None:
    models = tmp_path / "models"
    models.mkdir()
    # an L of two boxes, y-up like the Stanford files, saved under a name the script knows
    arm = trimesh.creation.box(extents=(0.3, 0.1, 0.1))
    post = trimesh.creation.box(extents=(0.1, 0.3, 0.1))
    post.apply_translation((-0.1, 0.1, 0.0))
    trimesh.util.concatenate([arm, post]).export(models / "bunny.obj")
    out = tmp_path / "agreement"
    cmd = [
        sys.executable, str(ROOT / "benchmarks" / "search_agreement.py"), "--models", str(models), "--out", str(out),
        "--only", "bunny.obj", "--yaws", "0,90", "--views", "2", "--extra", SMALL,
    ]  # fmt: skip
    proc = subprocess.run(cmd, capture_output=True, text=True, cwd=ROOT, timeout=600)
    assert proc.returncode in (0, 1), proc.stderr
    summary = json.loads((out / "agreement.json").read_text())["bunny.obj"]
    for search in ("fast", "exhaustive"):
        finals = [
            json.loads((out / "bunny" / f"yaw{yaw}" / search / "metrics.json").read_text())["final_coverage"]
            for yaw in ("0", "90")
        ]
        assert summary[search] == finals
        assert all(0.05 < c <= 1.0 for c in finals)
        doc = json.loads((out / "bunny" / "yaw90" / search / "metrics.json").read_text())
        assert doc["config"]["cluster"]["search"] == search
    mean_diff = statistics.mean(summary["fast"]) - statistics.mean(summary["exhaustive"])
    assert abs(summary["mean_diff"] - mean_diff) < 1e-12
    assert summary["within_limit"] == (abs(mean_diff) <= 0.01)
    assert proc.returncode == (0 if summary["within_limit"] else 1)
    assert "within 1 point" in proc.stdout and "bunny.obj" in proc.stdout
