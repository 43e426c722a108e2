"""``nbv bench --recorded`` and ``nbv scan --recorded`` on a small synthetic Stanford-format set."""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from nbv.cli import main
from tests.devices.test_recorded import stanford_folder


@pytest.mark.slow
def test_bench_and_scan_on_a_recorded_set(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    data = tmp_path / "scans"
    data.mkdir()
    stanford_folder(data)
    out = tmp_path / "bench"
    code = main(["bench", "--recorded", str(data), "--planners", "oracle,random", "--seeds", "2", "--out", str(out)])
    assert code == 0
    doc = json.loads((out / "results.json").read_text())
    assert [r["planner"] for r in doc["runs"]] == ["oracle", "random", "random"]
    assert 0.5 < doc["ceiling"] <= 1.0
    for run in doc["runs"]:
        assert sorted(run["order"]) == ["front", "side", "top"]
        assert run["order"][0] == "front"
        assert 1 <= run["views_to_95"] <= 4
        assert len(run["coverage"]) == 3 and run["coverage"][-1] == pytest.approx(doc["ceiling"], abs=0.02)
    summary = {r["planner"]: r for r in doc["summary"]}
    assert "random (mean of 2)" in summary and "views_to_95_sd" in summary["random (mean of 2)"]
    assert "| oracle |" in (out / "summary.md").read_text()
    scan_out = tmp_path / "scan"
    assert main(["scan", "--recorded", str(data), "--planner", "oracle", "--out", str(scan_out)]) == 0
    metrics = json.loads((scan_out / "metrics.json").read_text())
    assert [it["view"] for it in metrics["iterations"]] == doc["runs"][0]["order"]  # the oracle's, as in the bench
    assert (scan_out / "cloud.ply").stat().st_size > 0


def test_recorded_options_refuse_bad_input(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["bench", "--recorded", str(tmp_path / "missing")]) == 2
    assert "--recorded: " in capsys.readouterr().err
    assert main(["bench", "--recorded", str(tmp_path), "--planners", "nope"]) == 2
    assert "unknown planner 'nope'" in capsys.readouterr().err
    assert main(["bench", "--recorded", str(tmp_path), "--models", "sphere"]) == 2
    assert main(["bench", "--planners", "projection"]) == 2
    assert "--models: give at least one model" in capsys.readouterr().err
    with pytest.raises(SystemExit):
        main(["scan", "--recorded", str(tmp_path), "--model", "sphere"])  # one or the other
