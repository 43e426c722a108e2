"""The outputs of ``nbv bench``: results.csv, runs.json, summary.md, report.html and the plots.

Everything here works on the finished runs (:class:`workbench.evaluation.runs.RunOutcome`) of one bench and the
ceilings of its (model, placement) pairs. results.csv, per iteration:

- ``coverage``: fraction of the surface samples with a scanned point within 5 mm;
- ``reachable_coverage``: the ceiling of the run's (model, yaw) (empty without one), and
  ``coverage_ratio`` = coverage / ceiling;
- ``auc``, ``views_to_90``, ``views_to_95``, ``views_to_98``, ``time_to_90``, ``time_to_95``: the run's metrics
  (:mod:`workbench.evaluation.curves`; ``time_to_*`` the cumulative robot seconds when coverage / ceiling first
  reaches 90 / 95 %, the run's total plus its mean per view when never), repeated on each of its rows (filter on
  the last iteration for one a run);
- ``robot_seconds``: the view's robot time (move, plate turn, capture, planning); ``cumulative_robot_seconds``
  its running sum over the run; its parts ``move_seconds`` (the move's duration: turn, retract, trajectory; robot
  motion only, no computing), ``capture_seconds`` and ``motion_planning_seconds`` (wall times), and besides the
  plan's wall time ``plan_seconds`` its CPU time ``plan_cpu_seconds`` (``time.process_time``, which the machine's
  load inflates less);
- ``plan_seconds``: frame in -> next view out (integration, candidates, clustering, ellipsoids,
  scoring, selection), as in ``nbv scan``; preprocessing and ICP are timed apart;
- ``eval_seconds``: the candidate-evaluation stage alone (``timings["score"]``): for
  ``projection`` the projection of the ellipsoids, for the ray casters everything they do;
- ``fit_seconds``: ``projection``'s clustering + ellipsoid fitting (0 for the baselines).
  ``projection``'s full evaluation cost is eval + fit;
- ``precision_5mm``, ``recall_5mm``, ``fscore_5mm``, the same at 2 mm, ``chamfer_mm``: the cloud's accuracy
  after the view against the mesh (:mod:`workbench.evaluation.accuracy`; recall at 5 mm is the coverage);
- ``surface_fscore_5mm``: the reconstructed surface's F-score at 5 mm (TSDF of every registered frame,
  :mod:`workbench.surface`), on a run's last row only (empty on the others).

Plots: ``ratio.png`` (coverage / ceiling against view, one panel per model, mean over seeds and
placements with a ± one standard deviation band), ``robot.png`` (coverage / ceiling against the cumulative
robot seconds, a line per run), ``coverage.png`` (raw coverage, ceiling dashed),
``time.png`` (plan and evaluation time per view).
"""

from __future__ import annotations

import csv
import json
import math
import os
import statistics
from collections import defaultdict
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any

from nbv.bench_summary import run_metrics_of, summary_markdown
from workbench.evaluation import ACCURACY_COLUMNS, TIME_THRESHOLDS, RunOutcome

COLUMNS = (
    "model",
    "planner",
    "arm",
    "seed",
    "yaw",
    "iteration",
    "coverage",
    "reachable_coverage",
    "coverage_ratio",
    "points",
    "plan_seconds",
    "eval_seconds",
    "fit_seconds",
    "robot_seconds",
    "move_seconds",
    "capture_seconds",
    "motion_planning_seconds",
    "plan_cpu_seconds",
    "move_frames",
    "move_integration_seconds",
    "move_wait_seconds",
    "move_coverage",
    "auc",
    "views_to_90",
    "views_to_95",
    "views_to_98",
    "cumulative_robot_seconds",
    "time_to_90",
    "time_to_95",
    *ACCURACY_COLUMNS,
    "surface_fscore_5mm",
)
"""The columns of results.csv, in order."""

Row = dict[str, Any]
Ceilings = Mapping[tuple[str, float], float]
__all__ = ["COLUMNS", "result_rows", "summary_markdown", "write_report", "write_results"]


def result_rows(outcomes: Sequence[RunOutcome], ceilings: Ceilings, views: int) -> list[Row]:
    """Every iteration of every finished run, with the ceiling columns filled in where known."""
    metrics = run_metrics_of(outcomes, ceilings, views)
    rows: list[Row] = []
    for o in outcomes:
        ceiling = ceilings.get(o.ceiling_key)
        m = metrics.get((o.label, o.planner, o.seed, o.yaw))
        extra: Row = {"reachable_coverage": ceiling}
        if m is not None:
            extra |= {
                "auc": m.auc,
                "views_to_90": m.views_to[0],
                "views_to_95": m.views_to[1],
                "views_to_98": m.views_to[2],
            }
            extra |= {f"time_to_{round(100 * t)}": v for t, v in zip(TIME_THRESHOLDS, m.time_to, strict=False)}
        cumulative = 0.0
        for row in o.rows:
            ratio = row["coverage"] / ceiling if ceiling and row["coverage"] is not None else None
            cumulative += float(row.get("robot_seconds") or 0.0)
            rows.append({"yaw": o.yaw, **row, **extra, "coverage_ratio": ratio, "cumulative_robot_seconds": cumulative})
    return rows


def _atomic_write(path: Path, text: str | bytes) -> None:
    tmp = path.with_name(path.name + ".tmp")
    if isinstance(text, bytes):
        tmp.write_bytes(text)
    else:
        tmp.write_text(text)
    os.replace(tmp, path)


def write_results(out: Path, outcomes: Sequence[RunOutcome], ceilings: Ceilings | None = None, views: int = 0) -> None:
    """(Re)write out/results.csv and out/runs.json from the runs finished so far (atomically).

    views: N, the bench's ``--views`` (0: the longest run's)."""
    ceilings = ceilings or {}
    views = views or max((len(o.rows) for o in outcomes), default=1) or 1
    lines: list[str] = []

    class _Sink:
        def write(self, text: str) -> None:
            lines.append(text)

    writer = csv.DictWriter(_Sink(), fieldnames=COLUMNS, lineterminator="\n")
    writer.writeheader()
    for row in result_rows(outcomes, ceilings, views):
        writer.writerow({k: "" if row.get(k) is None else row[k] for k in COLUMNS})
    _atomic_write(out / "results.csv", "".join(lines))
    runs = [{**o.to_json(), "reachable_coverage": ceilings.get(o.ceiling_key)} for o in outcomes]
    _atomic_write(out / "runs.json", json.dumps(runs, indent=1))


# ---------------------------------------------------------------- plots


def _grid(n: int) -> tuple[int, int]:
    """(rows, columns) of the panel grid: near square, at most three columns."""
    cols = min(3, math.ceil(math.sqrt(n)))
    return math.ceil(n / cols), cols


def _by_iteration(outcomes: Sequence[RunOutcome], model: str, planner: str, key: str) -> tuple[list[int], list[float]]:
    """Iterations and the mean of ``key`` over seeds (skipping missing values)."""
    values: dict[int, list[float]] = defaultdict(list)
    for o in outcomes:
        if o.error is None and o.label == model and o.planner == planner:
            for r in o.rows:
                if r[key] is not None:
                    values[int(r["iteration"])].append(float(r[key]))
    its = sorted(values)
    return its, [statistics.fmean(values[i]) for i in its]


def plot(
    out: Path,
    outcomes: Sequence[RunOutcome],
    models: Sequence[str],
    planners: Sequence[str],
    ceilings: Ceilings | None = None,
    views: int = 0,
) -> list[str]:
    """Write out/coverage.png (coverage against view, reachable ceiling dashed), out/time.png (per
    iteration, log scale: plan time solid, evaluation incl. projection's fitting dotted) and, with
    ceilings, out/ratio.png (coverage / ceiling against view, ± one std band); one panel per model.
    Returns the file names written.
    """
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure
    from matplotlib.ticker import MaxNLocator

    ceilings = ceilings or {}
    views = views or max((len(o.rows) for o in outcomes), default=1) or 1
    colors = {p: f"C{i % 10}" for i, p in enumerate(planners)}
    nrows, ncols = _grid(max(1, len(models)))
    names = (["ratio", "robot"] if ceilings else []) + ["coverage", "time"]
    for name in names:
        fig = Figure(figsize=(4.2 * ncols, 3.4 * nrows), layout="constrained")
        FigureCanvasAgg(fig)
        axes = fig.subplots(nrows, ncols, squeeze=False).ravel()
        for k, (ax, model) in enumerate(zip(axes, models, strict=False)):
            for p in planners:
                if name == "ratio":
                    _ratio_panel(ax, outcomes, model, p, ceilings, views, colors[p])
                    continue
                if name == "robot":
                    _robot_panel(ax, outcomes, model, p, ceilings, colors[p])
                    continue
                if name == "coverage":
                    its, ys = _by_iteration(outcomes, model, p, "coverage")
                    ax.plot(its, ys, marker="o", ms=3, color=colors[p], label=p)
                    continue
                its, plan = _by_iteration(outcomes, model, p, "plan_seconds")
                ax.plot(its, [max(y, 1e-6) for y in plan], marker="o", ms=3, color=colors[p], label=f"{p} plan")
                its, ev = _by_iteration(outcomes, model, p, "eval_seconds")
                _, fit = _by_iteration(outcomes, model, p, "fit_seconds")
                full = [max(a + b, 1e-6) for a, b in zip(ev, fit, strict=True)]
                ax.plot(its, full, ls=":", color=colors[p], label=f"{p} eval" + (" + fit" if any(fit) else ""))
            if name in ("ratio", "robot"):
                for level in (0.9, 0.95):
                    ax.axhline(level, ls=":", lw=0.8, color="0.5")
                low = min((y for line in ax.get_lines() for y in line.get_ydata()), default=0.0)  # type: ignore[union-attr]
                ax.set_ylim(max(0.0, math.floor(10 * (float(low) - 0.05)) / 10), 1.02)
                ax.set_ylabel("coverage / ceiling")
            elif name == "coverage":
                values = [v for (m, _), v in ceilings.items() if m == model]
                if values:
                    ax.axhline(statistics.fmean(values), ls="--", color="0.4", label="reachable")
                ax.set_ylim(0.0, 1.02)
                ax.set_ylabel("coverage")
            else:
                ax.set_yscale("log")
                ax.set_ylabel("seconds per iteration")
            ax.set_title(model)
            ax.set_xlabel("robot seconds" if name == "robot" else "view")
            ax.xaxis.set_major_locator(MaxNLocator(integer=True))
            ax.grid(True, alpha=0.3)
            if k == 0:
                ax.legend(fontsize="small", loc="lower right" if name != "time" else "best")
        for ax in axes[len(models) :]:
            ax.set_visible(False)
        fig.suptitle(
            {
                "ratio": "coverage / reachable ceiling against view (mean ± std over seeds and placements)",
                "robot": "coverage / reachable ceiling against cumulative robot seconds (one line per run)",
                "coverage": "coverage against view",
                "time": "plan time (solid), candidate evaluation (dotted)",
            }[name]
        )
        fig.savefig(out / f"{name}.png", dpi=110)
    return [f"{n}.png" for n in names]


def _robot_panel(
    ax: Any, outcomes: Sequence[RunOutcome], model: str, planner: str, ceilings: Ceilings, color: str
) -> None:
    """One planner's runs of ``model``: coverage / ceiling against the cumulative robot seconds, a line per run."""
    first = True
    for o in outcomes:
        ceiling = ceilings.get(o.ceiling_key)
        if o.error is not None or o.label != model or o.planner != planner or not ceiling:
            continue
        xs, ys, total = [], [], 0.0
        for r in o.rows:
            total += float(r.get("robot_seconds") or 0.0)
            if r["coverage"] is not None:
                xs.append(total)
                ys.append(r["coverage"] / ceiling)
        ax.plot(xs, ys, marker="o", ms=2, lw=1, alpha=0.7, color=color, label=planner if first else None)
        first = False


def _ratio_panel(
    ax: Any, outcomes: Sequence[RunOutcome], model: str, planner: str, ceilings: Ceilings, views: int, color: str
) -> None:
    """One planner's mean coverage / ceiling curve over its runs of ``model``, with a ± std band."""
    from workbench.evaluation import ratio_curve

    curves = []
    for o in outcomes:
        ceiling = ceilings.get(o.ceiling_key)
        coverage = [r["coverage"] for r in o.rows if r["coverage"] is not None]
        if o.error is None and o.label == model and o.planner == planner and ceiling and coverage:
            curves.append(ratio_curve(coverage, ceiling, views))
    if not curves:
        return
    xs = list(range(1, views + 1))
    mean = [statistics.fmean(c[i] for c in curves) for i in range(views)]
    ax.plot(xs, mean, marker="o", ms=3, color=color, label=planner)
    if len(curves) > 1:
        std = [statistics.stdev(c[i] for c in curves) for i in range(views)]
        ax.fill_between(
            xs,
            [m - s for m, s in zip(mean, std, strict=True)],
            [m + s for m, s in zip(mean, std, strict=True)],
            color=color,
            alpha=0.15,
            lw=0,
        )


def write_report(
    out: Path, outcomes: Sequence[RunOutcome], meta: dict[str, Any], ceilings: Ceilings | None = None
) -> None:
    """results.csv, runs.json, meta.json (the bench's settings and wall times), summary.md, the plots and
    report.html (the summary and plots in one file)."""
    from nbv.bench_html import report_html

    ceilings = ceilings or {}
    write_results(out, outcomes, ceilings, meta["views"])
    _atomic_write(out / "meta.json", json.dumps(meta, indent=1))
    summary = summary_markdown(outcomes, meta, ceilings)
    _atomic_write(out / "summary.md", summary)
    images = plot(out, outcomes, meta["models"], meta["planners"], ceilings, meta["views"])
    _atomic_write(out / "report.html", report_html(summary, [out / name for name in images]))
