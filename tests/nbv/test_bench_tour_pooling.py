"""benchmarks/bench_tour.py: a run repeated in several bench directories counts once, with the mean over its
repetitions (the robot seconds' wall-clock parts change from bench to bench)."""

from __future__ import annotations

import csv
import importlib.util
import json
import sys
from pathlib import Path
from types import ModuleType

import pytest

ROOT = Path(__file__).resolve().parents[2]
COLUMNS = ["model", "planner", "seed", "yaw", "iteration", "coverage", "reachable_coverage", "robot_seconds"]
COLUMNS += ["plan_seconds", "plan_cpu_seconds", "move_seconds"]


@pytest.fixture(scope="module")
def bench_tour() -> ModuleType:
    spec = importlib.util.spec_from_file_location("bench_tour", ROOT / "benchmarks" / "bench_tour.py")
    assert spec is not None and spec.loader is not None
    module = importlib.util.module_from_spec(spec)
    sys.modules[spec.name] = module
    spec.loader.exec_module(module)
    return module


def bench_dir(path: Path, seconds: dict[tuple[str, str], float]) -> Path:
    """A bench directory: per (model, planner) one run of two views, coverage 0.5 then 0.96 of a ceiling of 1, the
    first view 1 robot second, the second ``seconds[(model, planner)]`` (so 95 % is reached at 1 + that)."""
    path.mkdir()
    runs = []
    with (path / "results.csv").open("w", newline="") as fh:
        writer = csv.DictWriter(fh, COLUMNS)
        writer.writeheader()
        for (model, planner), second in seconds.items():
            for iteration, coverage, robot in ((1, 0.5, 1.0), (2, 0.96, second)):
                writer.writerow(
                    {
                        "model": model,
                        "planner": planner,
                        "seed": 0,
                        "yaw": 0.0,
                        "iteration": iteration,
                        "coverage": coverage,
                        "reachable_coverage": 1.0,
                        "robot_seconds": robot,
                        "plan_seconds": 0.1,
                        "plan_cpu_seconds": 0.05,
                        "move_seconds": robot - 0.1,
                    }
                )
            runs.append(
                {"model": model, "planner": planner, "seed": 0, "yaw": 0.0, "poses": [], "terminated": "max_views"}
                | {"seconds": 1.0, "error": None}
            )
    (path / "runs.json").write_text(json.dumps(runs))
    return path


def robot_line(text: str) -> str:
    return next(line for line in text.splitlines() if line.strip().startswith("robot s to 95 %"))


def test_repeated_runs_are_pooled_by_their_mean(
    bench_tour: ModuleType, tmp_path: Path, capsys: pytest.CaptureFixture[str], monkeypatch: pytest.MonkeyPatch
) -> None:
    first = bench_dir(
        tmp_path / "a",
        {("m1", "projection"): 9.0, ("m1", "tour"): 6.0, ("m2", "projection"): 8.0, ("m2", "tour"): 5.0},
    )
    again = bench_dir(
        tmp_path / "b",
        {("m1", "projection"): 11.0, ("m1", "tour"): 6.0, ("m2", "projection"): 10.0, ("m2", "tour"): 5.0},
    )
    monkeypatch.setattr(sys, "argv", ["bench_tour.py", str(first)])
    bench_tour.main()
    single = capsys.readouterr().out
    assert "reps" not in single
    assert "6.50 vs     9.50, -31.6 %" in robot_line(single)  # (7 + 6) / 2 against (10 + 9) / 2
    monkeypatch.setattr(sys, "argv", ["bench_tour.py", str(first), str(again)])
    bench_tour.main()
    pooled = capsys.readouterr().out
    assert "68" not in pooled and "2 pairs (2 reps)" in pooled
    assert "6.50 vs    10.50, -38.1 %" in robot_line(pooled)  # projection m1 (10 + 12) / 2, m2 (9 + 11) / 2
