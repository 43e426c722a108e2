"""``nbv bench``: a tiny end-to-end bench (inline and with worker processes), the summary's numbers, bad input."""

from __future__ import annotations

import csv
import json
import struct
from pathlib import Path
from typing import Any

import pytest

from nbv.bench import RunOutcome, RunTask, run_tasks
from nbv.bench_report import COLUMNS, result_rows, summary_markdown
from nbv.cli import main
from planner.config import PlannerConfig
from planner.evaluators import EVALUATORS

TINY = ["--views", "2", "--candidates", "40", "--resolution", "0.02", "--t-min", "2", "--t-max", "6"]


def bench(out: Path, *extra: str) -> int:
    cache = ["--ceiling-cache", str(out / "ceilings")]
    return main(
        ["bench", "--models", "l-block", "--planners", "projection,random", *TINY, "--out", str(out), *cache, *extra]
    )


def read_csv(path: Path) -> list[dict[str, str]]:
    with path.open(newline="") as f:
        return list(csv.DictReader(f))


def png_size(path: Path) -> tuple[int, int]:
    """(width, height) from a PNG's IHDR; fails if the file is not a PNG."""
    data = path.read_bytes()
    assert data[:8] == b"\x89PNG\r\n\x1a\n", f"{path.name} is not a PNG"
    assert data[12:16] == b"IHDR"
    return struct.unpack(">II", data[16:24])


@pytest.fixture(scope="module")
def inline(tmp_path_factory: pytest.TempPathFactory) -> Path:
    out = tmp_path_factory.mktemp("bench1")
    assert bench(out, "--jobs", "1") == 0
    return out


@pytest.fixture(scope="module")
def pooled(tmp_path_factory: pytest.TempPathFactory) -> Path:
    out = tmp_path_factory.mktemp("bench2")
    assert bench(out, "--jobs", "2", "--no-reachable") == 0
    return out


def check_outputs(out: Path, reachable: bool) -> list[dict[str, str]]:
    rows = read_csv(out / "results.csv")
    assert tuple(rows[0]) == COLUMNS
    assert len(rows) == 2 * 2  # 2 planners x 1 seed x 2 views
    assert sorted((r["planner"], r["iteration"]) for r in rows) == [
        ("projection", "1"),
        ("projection", "2"),
        ("random", "1"),
        ("random", "2"),
    ]
    for r in rows:
        assert r["model"] == "l-block" and r["seed"] == "0"
        assert 0.0 < float(r["coverage"]) <= 1.0
        assert int(r["points"]) > 0
        assert 0.0 < float(r["eval_seconds"]) < float(r["plan_seconds"])
        assert (float(r["fit_seconds"]) > 0.0) == (r["planner"] == "projection")
        # the final surface's F@5mm on a run's last row only, at or below 1 and not far below the cloud's
        if r["iteration"] == "2":
            assert float(r["fscore_5mm"]) - 0.1 < float(r["surface_fscore_5mm"]) <= 1.0
        else:
            assert r["surface_fscore_5mm"] == ""
    ceilings = {r["reachable_coverage"] for r in rows}
    if reachable:  # computed once per (model, placement) and shared by every planner's rows
        assert len(ceilings) == 1
        ceiling = float(ceilings.pop())
        assert max(float(r["coverage"]) for r in rows) <= ceiling + 0.02
        for r in rows:
            assert float(r["coverage_ratio"]) == pytest.approx(float(r["coverage"]) / ceiling)
            assert 1 <= int(r["views_to_90"]) <= int(r["views_to_95"]) <= int(r["views_to_98"]) <= 3
            assert 0.0 < float(r["auc"]) <= 1.05
        assert len(list((out / "ceilings").glob("*.json"))) == 1
    else:
        assert ceilings == {""} and {r["auc"] for r in rows} == {""}

    runs = json.loads((out / "runs.json").read_text())
    assert {r["planner"] for r in runs} == {"projection", "random"}
    first = [r["poses"][0] for r in runs]
    assert first[0] == first[1], "every planner must start from the same view"
    first_cov = {r["coverage"] for r in rows if r["iteration"] == "1"}
    assert len(first_cov) == 1, "same first view and camera seed -> same first coverage"

    text = (out / "summary.md").read_text()
    headings = ["## Total planning time (s)", "## Ratio, baseline over projection", "## Coverage at view 2"]
    headings += ["## Coverage against the ceiling", "## Paired comparison against projection"]
    for heading in headings:
        assert heading in text
    if reachable:
        assert "| random | coverage / ceiling at the last view | 1 |" in text
        assert "| random | surface F@5mm at the last view | 1 |" in text
    page = (out / "report.html").read_text()
    assert page.startswith("<!DOCTYPE html>") and "<table>" in page and "data:image/png;base64," in page
    assert "<h2>Paired comparison against projection</h2>" in page
    assert "| planner | l-block | average per iteration |" in text
    assert "| random |" in text and "×" in text
    assert "eval + fit" in text
    for name in ("coverage.png", "time.png", *(["ratio.png", "robot.png"] if reachable else [])):
        width, height = png_size(out / name)
        assert width > 200 and height > 200
    return rows


@pytest.mark.slow
def test_inline_bench_writes_every_output(inline: Path) -> None:
    check_outputs(inline, reachable=True)


def test_pooled_bench_writes_every_output(pooled: Path, inline: Path) -> None:
    rows = check_outputs(pooled, reachable=False)
    # The first view does not depend on how the runs are scheduled.
    first = json.loads((inline / "runs.json").read_text())[0]["poses"][0]
    assert all(r["poses"][0] == first for r in json.loads((pooled / "runs.json").read_text()))
    assert {r["coverage"] for r in rows if r["iteration"] == "1"} == {
        r["coverage"] for r in read_csv(inline / "results.csv") if r["iteration"] == "1"
    }


class _Boom:
    name = "boom"

    def __init__(self, config: PlannerConfig) -> None:
        pass

    def reset(self) -> None:
        pass

    def evaluate(self, ctx: Any) -> Any:
        raise RuntimeError("boom\nat evaluation")


def test_a_failed_run_keeps_the_others(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str]
) -> None:
    monkeypatch.setitem(EVALUATORS, "boom", _Boom)
    args = ["--models", "box", "--planners", "random,boom", *TINY, "--jobs", "1", "--no-reachable"]
    code = main(["bench", *args, "--out", str(tmp_path)])
    assert code == 1
    err = capsys.readouterr().err
    assert "failed run box / boom / seed 0: RuntimeError: boom at evaluation" in err
    assert {r["planner"] for r in read_csv(tmp_path / "results.csv")} == {"random"}
    assert "RuntimeError: boom at evaluation" in (tmp_path / "summary.md").read_text()
    assert "Projection did not take part" in (tmp_path / "summary.md").read_text()


def test_worker_failure_is_one_outcome(tmp_path: Path) -> None:
    config = PlannerConfig().replace(termination={"max_views": 1}, voxel={"resolution": 0.02}, candidates={"count": 40})
    good = RunTask("box", "box", "random", 0, config)
    bad = RunTask(str(tmp_path / "missing.ply"), "missing", "random", 0, config)
    outcomes: list[RunOutcome] = []
    run_tasks([good, bad], 2, outcomes.append)
    by_label = {o.label: o for o in outcomes}
    assert by_label["box"].error is None and len(by_label["box"].rows) == 1
    assert by_label["missing"].rows == [] and "missing.ply" in (by_label["missing"].error or "")


def _outcome(planner: str, evals: list[float], fits: list[float], cov: float) -> RunOutcome:
    rows = [
        {
            "model": "m",
            "planner": planner,
            "seed": 0,
            "iteration": i + 1,
            "coverage": cov,
            "points": 10,
            "plan_seconds": 2 * e + f,
            "eval_seconds": e,
            "fit_seconds": f,
        }
        for i, (e, f) in enumerate(zip(evals, fits, strict=True))
    ]
    rows[-1]["surface_fscore_5mm"] = cov + 0.1  # the final surface's F@5mm, on the last row
    return RunOutcome("m", planner, 0, rows=rows, terminated="max_views", seconds=1.0)


def test_summary_numbers() -> None:
    outcomes = [
        _outcome("projection", [0.01, 0.03], [0.02, 0.02], 0.8),  # eval 0.02, eval+fit 0.04, plan 0.06 per iteration
        _outcome("raycast-oa", [1.0, 3.0], [0.0, 0.0], 0.7),  # eval 2.0, plan 4.0
    ]
    meta = {
        "models": ["m"],
        "planners": ["projection", "raycast-oa"],
        "seeds": [0],
        "views": 2,
        "resolution": 0.02,
        "candidates": 40,
        "jobs": 1,
        "threads": None,
        "wall_seconds": 1.0,
    }
    text = summary_markdown(outcomes, meta, {("m", 0.0): 0.9})
    assert "| projection | 0.120 | 0.060 |" in text  # total plan time, average per iteration
    assert "| raycast-oa | 8.000 | 4.000 |" in text
    assert "| raycast-oa | 100.0× | 50.0× | 66.7× |" in text
    assert "| projection | 0.8000 | 0.8000 |" in text
    assert "| reachable (ceiling) | 0.9000 | 0.9000 |" in text
    # coverage / ceiling: projection 0.8 / 0.9 at both views, raycast-oa 0.7 / 0.9
    assert "| projection | 0.8889 | 0.8889 | 3.00 | 3.00 | 3.00 | – | – |" in text  # no robot seconds: no times
    assert "| raycast-oa | coverage / ceiling at the last view | 1 | -0.1111 | – | 0 / 0 / 1 |" in text
    assert "| raycast-oa | views to 95 % of the ceiling | 1 | +0.00 | – | 0 / 1 / 0 |" in text
    assert "| raycast-oa | surface F@5mm at the last view | 1 | -0.1000 | – | 0 / 0 / 1 |" in text


def test_summary_and_rows_give_robot_time_to_coverage() -> None:
    fast, slow = _outcome("tour", [0.1, 0.1, 0.1], [0, 0, 0], 0.9), _outcome("projection", [0.1] * 3, [0] * 3, 0.9)
    for o, seconds, coverage in ((fast, [1.0, 2.0, 3.0], [0.5, 0.86, 0.9]), (slow, [1.0, 5.0, 5.0], [0.5, 0.82, 0.85])):
        for row, t, c in zip(o.rows, seconds, coverage, strict=True):
            row["robot_seconds"], row["coverage"] = t, c
    meta = {"models": ["m"], "planners": ["projection", "tour"], "seeds": [0], "views": 3, "resolution": 0.02}
    meta |= {"candidates": 40, "jobs": 1, "threads": None, "wall_seconds": 1.0}
    text = summary_markdown([slow, fast], meta, {("m", 0.0): 0.9})
    # ceiling 0.9: tour reaches 90 % (0.81) at view 2 (3 s) and 95 % (0.855) at view 2 too; projection reaches
    # 90 % at view 2 (6 s) and 95 % never: its total 11 s plus its mean per view 11 / 3 s
    assert "| tour | robot seconds to 90 % of the ceiling | 1 | -3.00 | – | 1 / 0 / 0 |" in text
    assert "| tour | robot seconds to 95 % of the ceiling | 1 | -11.67 | – | 1 / 0 / 0 |" in text
    rows = {(r["planner"], r["iteration"]): r for r in result_rows([slow, fast], {("m", 0.0): 0.9}, 3)}
    assert rows[("projection", 3)]["cumulative_robot_seconds"] == pytest.approx(11.0)
    assert rows[("projection", 1)]["time_to_95"] == pytest.approx(11.0 * 4 / 3)
    assert rows[("tour", 1)]["time_to_90"] == rows[("tour", 1)]["time_to_95"] == pytest.approx(3.0)


@pytest.mark.parametrize(
    ("extra", "message"),
    [
        (["--models", "l-block", "--planners", "projection,nope"], "--planners: unknown planner 'nope'"),
        (["--models", "l-block", "--planners", "random,random"], "--planners: 'random' is listed twice"),
        (["--models", "/no/such/mesh.ply"], "--models:"),
        (["--models", "l-block", "--views", "0"], "--views: must be >= 1, got 0"),
        (["--models", "l-block", "--jobs", "0"], "--jobs: must be >= 1, got 0"),
        (["--models", "l-block", "--seeds", "0"], "--seeds: must be >= 1, got 0"),
        (["--models", "l-block", "--yaws", "0,x"], "--yaws: expected comma-separated degrees"),
        (["--models", "l-block", "--yaws", "0,90,0"], "--yaws: 0 is listed twice"),
        (["--models", "l-block", "--planners", "random", "--reference", "projection"], "--reference: 'projection'"),
        (["--models", "l-block", "--address", "tcp://127.0.0.1:1"], "--address: only with --executor dask"),
        (["--models", "l-block", "--executor", "dask", "--workers", "0"], "--workers: must be >= 1, got 0"),
    ],
)
def test_bad_input_is_one_line_before_any_work(
    tmp_path: Path, capsys: pytest.CaptureFixture[str], extra: list[str], message: str
) -> None:
    out = tmp_path / "out"
    assert main(["bench", *extra, "--out", str(out)]) == 2
    err = capsys.readouterr().err.strip()
    assert err.startswith("nbv: error: ") and message in err and "\n" not in err
    assert not out.exists()


def test_yaw_reaches_every_run(tmp_path: Path) -> None:
    from nbv.bench import make_tasks
    from nbv.cli import build_parser

    args = build_parser().parse_args(["bench", "--models", "l-block", "--planners", "projection,random", "--yaw", "90"])
    tasks = make_tasks(args)
    assert len(tasks) == 2 and all(t.yaw_deg == 90.0 for t in tasks)
    config = PlannerConfig().replace(termination={"max_views": 1}, voxel={"resolution": 0.02}, candidates={"count": 40})
    points = {}
    for yaw in (0.0, 90.0):
        outcomes: list[RunOutcome] = []
        run_tasks([RunTask("l-block", "l", "random", 0, config, yaw_deg=yaw)], 1, outcomes.append)
        points[yaw] = outcomes[0].rows[0]["points"]
    assert points[0.0] != points[90.0]  # the first view sees another side of the turned object
