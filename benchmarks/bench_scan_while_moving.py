"""Scan while moving: every planner with capture during moves against stop-and-go ``projection``, from finished
``nbv bench`` runs (docs/experiments/scan-while-moving.md).

Reads the results.csv and runs.json of bench directories given as ``LABEL=DIR`` (the label names how they ran, e.g.
``stop=out/swm-stop`` for ``--move-capture 0`` and ``move=out/swm-move`` for ``--move-capture 2.5``), pairs the runs
by (model, seed, placement) with the reference (``--reference "projection stop"``: planner and label), and prints
one markdown row per (planner, label):

- robot seconds to 90 % and 95 % of the ceiling (median over the runs; a move frame counts at its time,
  ``workbench.evaluation.curves.time_to_reach``);
- the geometric mean of the paired per-run ratios to the reference's robot seconds to 95 % (and 90 %) with the
  95 % t-interval on the log ratios; and of the ratios to 95 % with every plan's CPU seconds in place of its wall
  seconds (robot time counts the plan's wall seconds, which follow the shared machine's load), and counting the
  moves alone (the robot's own seconds; a move frame at its time);
- F@5mm of the cloud and of the surface at the last view (mean) and the paired difference to the reference in points;
- the median plan seconds per view (and its CPU seconds: the machine is shared, the wall seconds follow its load);
- integration against the moves: the integration seconds of the move frames over the moves' modelled seconds, the
  largest wait of a move for its integration as a share of the move, and the share of moves that waited > 10 %.

    M="../shared/models/*.obj ../shared/models/*.ply ../shared/models/extra/*.obj ../shared/models/extra/*.off"
    S="--arm ur5 --sensor realsense-d435 --calibration typical --seeds 2"
    nbv bench --models $M --planners projection $S --out out/swm-stop
    nbv bench --models $M --planners tour,path,projection $S --move-capture 2.5 --turn-while-moving \
        --out out/swm-move
    nbv bench --models $M --planners tour $S --turn-while-moving --out out/swm-stop-turn
    .venv/bin/python benchmarks/bench_scan_while_moving.py stop=out/swm-stop move+turn=out/swm-move \
        stop+turn=out/swm-stop-turn
"""

from __future__ import annotations

import argparse
import csv
import json
import math
import statistics
from dataclasses import dataclass, field
from pathlib import Path

from scipy import stats

from workbench.evaluation import move_points, run_metrics

WAIT_LIMIT = 0.1
"""A move may wait for the integration of its frames by at most this share of its time (the issue's bound)."""


@dataclass
class Run:
    """One finished run: its rows (one per view, in order) and the label of its bench directory."""

    model: str
    planner: str
    seed: int
    yaw: float
    label: str
    rows: list[dict[str, str]] = field(default_factory=list)

    @property
    def key(self) -> tuple[str, int, float]:
        return (self.model, self.seed, self.yaw)

    def column(self, name: str) -> list[float | None]:
        return [None if r.get(name) in (None, "") else float(r[name]) for r in self.rows]


def load(label: str, directory: Path) -> list[Run]:
    """The runs of a bench directory that finished without an error."""
    by_key: dict[tuple[str, str, int, float], list[dict[str, str]]] = {}
    with (directory / "results.csv").open() as fh:
        for row in csv.DictReader(fh):
            key = (row["model"], row["planner"], int(float(row["seed"])), float(row["yaw"]))
            by_key.setdefault(key, []).append(row)
    runs = []
    for run in json.loads((directory / "runs.json").read_text()):
        key = (run["model"], run["planner"], int(run["seed"]), float(run["yaw"]))
        rows = sorted(by_key.get(key, []), key=lambda r: int(float(r["iteration"])))
        if run.get("error") is None and rows:
            runs.append(Run(*key, label, rows))
    return runs


@dataclass
class Measured:
    """What one run measured (see the module docstring)."""

    time_to: tuple[float, float]
    time_to_95_cpu: float
    time_to_95_moves: float
    """Robot seconds to 95 % counting the moves alone (no capture, plan or motion planning: what the robot does)."""
    """Robot seconds to 95 % with each plan's CPU seconds in place of its wall seconds (less dependent on the load)."""
    fscore: float | None
    surface_fscore: float | None
    plan: list[float]
    plan_cpu: list[float]
    integration: float
    move: float
    waits: list[float]


def measure(run: Run) -> Measured | None:
    """The run's metrics against its ceiling, None without a ceiling or coverage."""
    ceiling = next((float(r["reachable_coverage"]) for r in run.rows if r.get("reachable_coverage")), None)
    coverage = [c for c in run.column("coverage") if c is not None]
    if not ceiling or len(coverage) != len(run.rows):
        return None
    robot = [float(s or 0.0) for s in run.column("robot_seconds")]
    plan = [float(s or 0.0) for s in run.column("plan_seconds")]
    cpu = [float(s or 0.0) for s in run.column("plan_cpu_seconds")]
    moves = [move_points(r.get("move_coverage")) for r in run.rows]
    metrics = run_metrics(coverage, ceiling, len(run.rows), robot, moves)
    as_cpu = [r - p + c for r, p, c in zip(robot, plan, cpu, strict=True)]  # the plan's CPU in place of its wall time
    metrics_cpu = run_metrics(coverage, ceiling, len(run.rows), as_cpu, moves)
    move = [float(s or 0.0) for s in run.column("move_seconds")]
    metrics_moves = run_metrics(coverage, ceiling, len(run.rows), move, moves)
    wait = [float(s or 0.0) for s in run.column("move_wait_seconds")]
    last = run.rows[-1]
    return Measured(
        (float(metrics.time_to[0]), float(metrics.time_to[1])),
        float(metrics_cpu.time_to[1]),
        float(metrics_moves.time_to[1]),
        float(last["fscore_5mm"]) if last.get("fscore_5mm") else None,
        float(last["surface_fscore_5mm"]) if last.get("surface_fscore_5mm") else None,
        [float(s or 0.0) for s in run.column("plan_seconds")],
        [float(s or 0.0) for s in run.column("plan_cpu_seconds")],
        sum(float(s or 0.0) for s in run.column("move_integration_seconds")),
        sum(move),
        [w / m for w, m in zip(wait, move, strict=True) if m > 0],
    )


def geometric_interval(ratios: list[float]) -> tuple[float, float | None, float | None]:
    """(geometric mean, low, high): the 95 % t-interval of the mean log ratio, exponentiated (None, None for one)."""
    logs = [math.log(r) for r in ratios]
    mean = statistics.fmean(logs)
    if len(logs) < 2:
        return math.exp(mean), None, None
    half = float(stats.t.ppf(0.975, len(logs) - 1)) * statistics.stdev(logs) / math.sqrt(len(logs))
    return math.exp(mean), math.exp(mean - half), math.exp(mean + half)


def mean_interval(values: list[float]) -> tuple[float, float | None, float | None]:
    """(mean, low, high): the 95 % t-interval of the mean (None, None for one value)."""
    mean = statistics.fmean(values)
    if len(values) < 2:
        return mean, None, None
    half = float(stats.t.ppf(0.975, len(values) - 1)) * statistics.stdev(values) / math.sqrt(len(values))
    return mean, mean - half, mean + half


def _ci(value: tuple[float, float | None, float | None], digits: int, scale: float = 1.0) -> str:
    mid, low, high = value
    if low is None or high is None:
        return f"{scale * mid:.{digits}f}"
    return f"{scale * mid:.{digits}f} [{scale * low:.{digits}f}, {scale * high:.{digits}f}]"


def table(runs: list[Run], reference: tuple[str, str]) -> list[str]:
    """The markdown table (see the module docstring) of every (planner, label) against ``reference``."""
    measured: dict[tuple[str, str], dict[tuple[str, int, float], Measured]] = {}
    for run in runs:
        m = measure(run)
        if m is not None:
            measured.setdefault((run.planner, run.label), {})[run.key] = m
    ref = measured.get(reference, {})
    lines = [
        "| planner | capture | runs | robot s to 90 % | robot s to 95 % | × stop-and-go to 95 % [95 % CI] "
        "| × to 90 % [95 % CI] | × to 95 %, plan as CPU s | × to 95 %, moves only | F@5mm cloud | Δ points | F@5mm surface | Δ points | plan s (median; CPU) "
        "| integration / move s | largest wait | moves waiting > 10 % |",
        "| --- | --- | ---: | ---: | ---: | ---: | ---: | ---: | ---: | ---: | ---: | ---: | ---: | ---: | ---: | ---: | ---: |",
    ]
    order = sorted(measured, key=lambda k: (k != reference, k[1], k[0]))
    for who in order:
        mine = measured[who]
        shared = sorted(set(mine) & set(ref))
        cells = [who[0], who[1], str(len(mine))]
        cells += [f"{statistics.median(m.time_to[i] for m in mine.values()):.1f}" for i in (0, 1)]
        for get in (
            lambda m: m.time_to[1],
            lambda m: m.time_to[0],
            lambda m: m.time_to_95_cpu,
            lambda m: m.time_to_95_moves,
        ):
            ratios = [get(mine[k]) / get(ref[k]) for k in shared if get(ref[k]) > 0]
            cells.append(
                _ci(geometric_interval(ratios), 2) + f" ({len(ratios)})" if ratios and who != reference else "–"
            )
        for attr in ("fscore", "surface_fscore"):
            values = [getattr(m, attr) for m in mine.values() if getattr(m, attr) is not None]
            cells.append(f"{100 * statistics.fmean(values):.1f}" if values else "–")
            diffs = [
                getattr(mine[k], attr) - getattr(ref[k], attr)
                for k in shared
                if getattr(mine[k], attr) is not None and getattr(ref[k], attr) is not None
            ]
            cells.append(_ci(mean_interval(diffs), 1, 100.0) if diffs and who != reference else "–")
        plan = [s for m in mine.values() for s in m.plan]
        cpu = [s for m in mine.values() for s in m.plan_cpu]
        cells.append(f"{statistics.median(plan):.3f}; {statistics.median(cpu):.3f}")
        integration = sum(m.integration for m in mine.values())
        move = sum(m.move for m in mine.values())
        waits = [w for m in mine.values() for w in m.waits]
        cells.append(f"{integration:.0f} / {move:.0f}" if integration else "–")
        cells.append(f"{100 * max(waits):.0f} %" if waits and integration else "–")
        over = sum(w > WAIT_LIMIT + 1e-9 for w in waits)
        cells.append(f"{over} of {len(waits)}" if waits and integration else "–")
        lines.append("| " + " | ".join(cells) + " |")
    return lines


def main() -> None:
    parser = argparse.ArgumentParser(description=(__doc__ or "").splitlines()[0])
    parser.add_argument("dirs", nargs="+", help="LABEL=DIR: nbv bench output directories and how they ran")
    parser.add_argument("--reference", default="projection stop", help="PLANNER LABEL of the reference runs")
    args = parser.parse_args()
    runs: list[Run] = []
    for spec in args.dirs:
        label, _, directory = spec.partition("=")
        if not directory:
            parser.error(f"{spec!r}: expected LABEL=DIR")
        runs += load(label, Path(directory))
    planner, _, label = args.reference.rpartition(" ")
    print("\n".join(table(runs, (planner, label))))


if __name__ == "__main__":
    main()
