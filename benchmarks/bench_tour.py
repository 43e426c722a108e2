"""Robot time to coverage: the ``tour`` planner against the greedy ones, from finished ``nbv bench`` runs
(docs/experiments/tour.md).

Reads the results.csv and runs.json of one or more bench directories (e.g. one with ``projection,tour`` on every
mesh and one with ``raycast-apora`` on fewer), pairs the runs by (model, seed, placement), and prints for every
planner against ``--reference`` (and ``--also``): the mean robot seconds to 95 % / 90 % of the ceiling, the
relative change of the mean, the paired mean difference with its 95 % t-interval, the AUC over views and final
coverage / ceiling differences (points), and the median plan time. Plan seconds count in robot time and grow with
the machine's load, so three load-independent variants of the robot seconds to 95 % follow (the reported metric
itself is unchanged): without the plan's seconds (moves, captures, motion planning); with the plan's CPU seconds in
place of its wall seconds (``plan_cpu_seconds``); and the moves alone (``move_seconds``: turns, retracts and
trajectories, no computing at all: what the robot itself does). The last two need benches that wrote those
columns (their runs are left out otherwise). (``nbv bench`` writes the same robot-time rows into its own
summary.md; this script pairs runs of several benches.)

Repetitions: a run (model, planner, seed, placement) found in several directories counts once, with each metric the
mean over its repetitions (``reps`` in the header). The runs are deterministic in what the robot does but not in
the plan's and the simulated capture's wall seconds, which change with the machine's speed and the other bench job
on the cores: the same code measured an hour apart moved the robot seconds to 95 % of `projection` by 0.1-0.3 s
(docs/experiments/tour.md), so a comparison at the edge of a goal should pool benches of both planners run at
several times.

    nbv bench --models ../shared/models/*.{obj,ply} ../shared/models/extra/*.{obj,off} \\
        --planners projection,tour --seeds 2 --yaws 0,90 --out out/tour-ideal
    .venv/bin/python benchmarks/bench_tour.py out/tour-ideal [more dirs] [--reference projection]
"""

from __future__ import annotations

import argparse
import csv
import json
import statistics
from pathlib import Path
from typing import Any

from workbench.evaluation import RunMetrics, RunOutcome, paired_comparison, run_metrics

INTEGER = {"seed", "iteration", "points", "views_to_90", "views_to_95", "views_to_98"}
TEXT = {"model", "planner"}


def _value(key: str, text: str) -> Any:
    if text == "":
        return None
    if key in TEXT:
        return text
    return int(float(text)) if key in INTEGER else float(text)


def load(directory: Path) -> tuple[list[RunOutcome], dict[tuple[str, float], float]]:
    """The finished runs of a bench directory and its ceilings per (model, yaw)."""
    rows: dict[tuple[str, str, int, float], list[dict[str, Any]]] = {}
    ceilings: dict[tuple[str, float], float] = {}
    with (directory / "results.csv").open() as fh:
        for raw in csv.DictReader(fh):
            row = {k: _value(k, v) for k, v in raw.items()}
            key = (row["model"], row["planner"], row["seed"], row["yaw"])
            rows.setdefault(key, []).append(row)
            if row["reachable_coverage"] is not None:
                ceilings[(row["model"], row["yaw"])] = row["reachable_coverage"]
    outcomes = []
    for run in json.loads((directory / "runs.json").read_text()):
        key = (run["model"], run["planner"], run["seed"], float(run["yaw"]))
        o = RunOutcome(run["model"], run["planner"], run["seed"], float(run["yaw"]))
        o.rows = sorted(rows.get(key, []), key=lambda r: r["iteration"])
        o.poses, o.terminated, o.seconds, o.error = run["poses"], run["terminated"], run["seconds"], run["error"]
        o.refused_moves, o.icp_rejected = run.get("refused_moves", []), run.get("icp_rejected", [])
        outcomes.append(o)
    return outcomes, ceilings


SECONDS = ("robot", "less plan", "plan cpu", "moves")
"""What :func:`metrics_of` counts as a view's seconds: ``robot_seconds`` (the reported metric); less the plan's
wall seconds; with the plan's CPU seconds in place of its wall seconds; the move's duration alone."""


def view_seconds(row: dict[str, Any], kind: str) -> float | None:
    """A results.csv row's seconds of ``kind`` (:data:`SECONDS`); None when the bench did not write them."""
    robot, plan = float(row["robot_seconds"] or 0.0), float(row["plan_seconds"] or 0.0)
    if kind == "robot":
        return robot
    if kind == "less plan":
        return robot - plan
    if kind == "plan cpu":
        cpu = row.get("plan_cpu_seconds")
        return None if cpu is None else robot - plan + float(cpu)
    move = row.get("move_seconds")
    return None if move is None else float(move)


def metrics_of(
    outcomes: list[RunOutcome], ceilings: dict[tuple[str, float], float], views: int, kind: str = "robot"
) -> dict[tuple[str, str, int, float], list[RunMetrics]]:
    """(model, planner, seed, yaw) -> the metrics of the run's repetitions (one per bench directory that holds it)
    with its robot times counted as ``kind`` (:data:`SECONDS`), for finished runs with a ceiling (and, for the
    variants that need them, the columns)."""
    out: dict[tuple[str, str, int, float], list[RunMetrics]] = {}
    for o in outcomes:
        ceiling = ceilings.get((o.label, o.yaw))
        rows = [r for r in o.rows if r["coverage"] is not None]
        if o.error is None and rows and ceiling:
            seconds = [view_seconds(r, kind) for r in rows]
            if any(s is None for s in seconds):
                continue
            out.setdefault((o.label, o.planner, o.seed, o.yaw), []).append(
                run_metrics([r["coverage"] for r in rows], ceiling, views, [float(s or 0.0) for s in seconds])
            )
    return out


def compare(outcomes: list[RunOutcome], ceilings: dict[tuple[str, float], float], views: int, reference: str) -> None:
    """Print every planner against ``reference`` over their shared (model, seed, yaw) runs."""
    metrics = metrics_of(outcomes, ceilings, views)
    variants = {kind: metrics_of(outcomes, ceilings, views, kind) for kind in SECONDS[1:]}
    planners = sorted({p for (_, p, _, _) in metrics})
    plan_seconds = {
        p: statistics.median(r["plan_seconds"] for o in outcomes if o.planner == p for r in o.rows) for p in planners
    }
    ref = {(m, s, y): v for (m, p, s, y), v in metrics.items() if p == reference}

    def reps(runs: dict[Any, list[RunMetrics]]) -> str:
        """The header's note of repetitions, e.g. " (3 reps)": the fewest and most of a run; "" when none repeats."""
        counts = {len(v) for v in runs.values()} or {1}
        low, high = min(counts), max(counts)
        if high == 1:
            return ""
        return f" ({low} reps)" if low == high else f" ({low}-{high} reps)"

    def runs_of(kind: str, who: str) -> dict[tuple[str, int, float], list[RunMetrics]]:
        """(model, seed, yaw) -> the repetitions of ``who``'s runs, their robot times counted as ``kind``."""
        return {(m, s, y): v for (m, q, s, y), v in variants[kind].items() if q == who}

    print(
        f"reference {reference}: {len(ref)} runs{reps(ref)}; "
        f"median plan {plan_seconds.get(reference, float('nan')):.3f} s"
    )
    for p in planners:
        if p == reference:
            continue
        mine = {(m, s, y): v for (m, q, s, y), v in metrics.items() if q == p}
        keys = sorted(set(mine) & set(ref))
        if not keys:
            continue
        print(f"\n{p} vs {reference}: {len(keys)} pairs{reps(mine)}; median plan {plan_seconds[p]:.3f} s")
        pairs_of = {kind: (runs_of(kind, p), runs_of(kind, reference)) for kind in SECONDS[1:]}
        lines = [("robot s to 95 %", lambda v: v.time_to[1], 1.0, (mine, ref))]
        for kind, label in zip(SECONDS[1:], ("less plan s", "plan as CPU s", "moves only"), strict=True):
            lines.append((f"  to 95 %, {label}", lambda v: v.time_to[1], 1.0, pairs_of[kind]))
        lines += [
            ("robot s to 90 %", lambda v: v.time_to[0], 1.0, (mine, ref)),
            ("  to 90 %, moves only", lambda v: v.time_to[0], 1.0, pairs_of["moves"]),
            ("AUC over views (points)", lambda v: v.auc, 100.0, (mine, ref)),
            ("final / ceiling (points)", lambda v: v.final_ratio, 100.0, (mine, ref)),
        ]
        for label, get, scale, (x, y) in lines:
            shared = [k for k in keys if k in x and k in y]
            if not shared:
                continue
            a = {k: scale * statistics.fmean(get(v) for v in x[k]) for k in shared}  # the mean over repetitions
            b = {k: scale * statistics.fmean(get(v) for v in y[k]) for k in shared}
            c = paired_comparison(a, b, higher_is_better=scale != 1.0)
            assert c is not None
            mean_a, mean_b = statistics.fmean(a.values()), statistics.fmean(b.values())
            change = f", {100 * (mean_a / mean_b - 1):+.1f} %" if scale == 1.0 else ""
            interval = "-" if c.low is None else f"[{c.low:+.2f}, {c.high:+.2f}]{' *' if c.significant else ''}"
            pairs = "" if len(shared) == len(keys) else f" ({len(shared)} pairs)"
            print(
                f"  {label:<26} {mean_a:8.2f} vs {mean_b:8.2f}{change}; paired {c.mean:+.2f} {interval}; "
                f"wins / ties / losses {c.wins} / {c.ties} / {c.losses}{pairs}"
            )


def main() -> None:
    parser = argparse.ArgumentParser(description=(__doc__ or "").splitlines()[0])
    parser.add_argument("dirs", nargs="+", type=Path, help="nbv bench output directories")
    parser.add_argument("--reference", default="projection")
    parser.add_argument("--also", default="raycast-apora", help="a second reference, when its runs are there")
    args = parser.parse_args()
    outcomes: list[RunOutcome] = []
    ceilings: dict[tuple[str, float], float] = {}
    for d in args.dirs:
        o, c = load(d)
        outcomes += o
        ceilings |= c
    views = max(len(o.rows) for o in outcomes)
    compare(outcomes, ceilings, views, args.reference)
    if any(o.planner == args.also for o in outcomes):
        print()
        compare(outcomes, ceilings, views, args.also)


if __name__ == "__main__":
    main()
