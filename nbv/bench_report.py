"""The outputs of ``nbv bench``: results.csv, runs.json, summary.md, coverage.png and time.png.

Everything here works on the finished runs (:class:`nbv.runs.RunOutcome`) of one bench.
Timing columns, per iteration:

- ``plan_seconds``: frame in -> next view out (integration, candidates, clustering, ellipsoids,
  scoring, selection), as in ``nbv scan``; preprocessing and ICP are timed apart;
- ``eval_seconds``: the candidate-evaluation stage alone (``timings["score"]``): for
  ``projection`` the projection of the ellipsoids, for the ray casters everything they do;
- ``fit_seconds``: ``projection``'s clustering + ellipsoid fitting (0 for the baselines).
  ``projection``'s full evaluation cost is eval + fit.
"""

from __future__ import annotations

import csv
import json
import math
import os
import statistics
from collections import defaultdict
from collections.abc import Sequence
from pathlib import Path
from typing import Any

from nbv.runs import RunOutcome

COLUMNS = (
    "model",
    "planner",
    "seed",
    "iteration",
    "coverage",
    "points",
    "plan_seconds",
    "eval_seconds",
    "fit_seconds",
    "robot_seconds",
    "reachable_coverage",
)
"""The columns of results.csv, in order."""

Row = dict[str, Any]


def ceilings(outcomes: Sequence[RunOutcome]) -> dict[tuple[str, int], float]:
    """(model, seed) -> reachable coverage, from the runs that computed it."""
    return {(o.label, o.seed): o.reachable_coverage for o in outcomes if o.reachable_coverage is not None}


def result_rows(outcomes: Sequence[RunOutcome]) -> list[Row]:
    """Every iteration of every finished run, with ``reachable_coverage`` filled in where known."""
    ceiling = ceilings(outcomes)
    return [{**row, "reachable_coverage": ceiling.get((o.label, o.seed))} for o in outcomes for row in o.rows]


def _atomic_write(path: Path, text: str) -> None:
    tmp = path.with_name(path.name + ".tmp")
    tmp.write_text(text)
    os.replace(tmp, path)


def write_results(out: Path, outcomes: Sequence[RunOutcome]) -> None:
    """(Re)write out/results.csv and out/runs.json from the runs finished so far (atomically)."""
    lines: list[str] = []

    class _Sink:
        def write(self, text: str) -> None:
            lines.append(text)

    writer = csv.DictWriter(_Sink(), fieldnames=COLUMNS, lineterminator="\n")
    writer.writeheader()
    for row in result_rows(outcomes):
        writer.writerow({k: "" if row.get(k) is None else row[k] for k in COLUMNS})
    _atomic_write(out / "results.csv", "".join(lines))
    _atomic_write(out / "runs.json", json.dumps([o.to_json() for o in outcomes], indent=1))


# ---------------------------------------------------------------- summary.md


def _mean(values: Sequence[float]) -> float | None:
    return statistics.fmean(values) if values else None


def _cell(values: Sequence[float], digits: int) -> str:
    """Mean (± std when there are several values) or an en dash when there are none."""
    if not values:
        return "–"
    text = f"{statistics.fmean(values):.{digits}f}"
    if len(values) > 1:
        text += f" ± {statistics.stdev(values):.{digits}f}"
    return text


def _fmt(value: float | None, digits: int) -> str:
    return "–" if value is None else f"{value:.{digits}f}"


def _ratio(num: float | None, den: float | None) -> str:
    if num is None or den is None or den <= 0:
        return "n/a"
    return f"{num / den:.1f}×"


def _table(header: Sequence[str], rows: Sequence[Sequence[str]], left: int = 1) -> list[str]:
    """A markdown table; the first ``left`` columns are text (left-aligned), the rest numbers."""
    align = ["---"] * left + ["---:"] * (len(header) - left)
    lines = ["| " + " | ".join(header) + " |", "| " + " | ".join(align) + " |"]
    return lines + ["| " + " | ".join(r) + " |" for r in rows]


def summary_markdown(outcomes: Sequence[RunOutcome], meta: dict[str, Any]) -> str:
    """summary.md: Table I (total planning time), evaluation time and ratios, coverage at the last view, runs."""
    models: list[str] = meta["models"]
    planners: list[str] = meta["planners"]
    views: int = meta["views"]
    ok = [o for o in outcomes if o.error is None and o.rows]
    runs: dict[tuple[str, str], list[RunOutcome]] = defaultdict(list)
    rows: dict[str, list[Row]] = defaultdict(list)
    model_rows: dict[tuple[str, str], list[Row]] = defaultdict(list)
    for o in ok:
        runs[(o.label, o.planner)].append(o)
        rows[o.planner].extend(o.rows)
        model_rows[(o.label, o.planner)].extend(o.rows)

    def col(planner: str, key: str, model: str | None = None) -> list[float]:
        source = rows[planner] if model is None else model_rows[(model, planner)]
        return [float(r[key]) for r in source]

    threads = meta.get("threads")
    out = [
        "# nbv bench",
        "",
        f"Models: {', '.join(models)}. Planners: {', '.join(planners)}. Views: {views}. "
        f"Seeds: {', '.join(map(str, meta['seeds']))}. Resolution {meta['resolution']} m, "
        f"{meta['candidates']} candidates. Jobs: {meta['jobs']}"
        + (f" ({threads} BLAS thread(s) per run)" if threads else " (inline)")
        + f"; wall time {meta['wall_seconds']:.1f} s.",
        "",
        "Every planner of a (model, seed) starts from the same view with the same seed for camera noise.",
        "With `--jobs` > 1 runs share the CPUs: ratios compare planners under the same load; for absolute",
        "times use `--jobs 1`.",
        "",
        "## Total planning time (s)",
        "",
        "Shaped like the paper's Table I: the sum of `plan_seconds` over a scan's views (mean over seeds);",
        "the last column is the mean `plan_seconds` per iteration over all models and seeds. `plan_seconds`",
        "includes integrating the new frame into the voxel map (the same work for every planner), not preprocessing or ICP.",
        "",
    ]
    header = ["planner", *models, "average per iteration"]
    body = []
    for p in planners:
        totals = [_cell([sum(r["plan_seconds"] for r in o.rows) for o in runs[(m, p)]], 3) for m in models]
        body.append([p, *totals, _fmt(_mean(col(p, "plan_seconds")), 3)])
    out += [*_table(header, body), "", "## Total robot time (s)", ""]
    out += [
        "The sum over a scan's views of the move durations (plate turn + timed joint trajectory), the captures,",
        "the planning and the motion planning (mean over seeds): what the scan costs at the robot.",
        "",
    ]
    body = []
    for p in planners:
        totals = [_cell([sum(r.get("robot_seconds") or 0.0 for r in o.rows) for o in runs[(m, p)]], 2) for m in models]
        per_view = [float(r.get("robot_seconds") or 0.0) for r in rows[p]]  # older runs lack the column
        body.append([p, *totals, _fmt(_mean(per_view), 2)])
    out += [*_table(header, body), "", "## Candidate evaluation time per iteration (s, mean)", ""]
    body = []
    for p in planners:
        ev, fit = col(p, "eval_seconds"), col(p, "fit_seconds")
        full = [a + b for a, b in zip(ev, fit, strict=True)]
        body.append([p, *(_fmt(_mean(x), 4) for x in (ev, fit, full, col(p, "plan_seconds")))])
    out += _table(["planner", "eval_seconds", "fit_seconds", "eval + fit", "plan_seconds"], body)
    out += [
        "",
        "`eval_seconds` is the candidate-evaluation stage alone. For projection it is the projection of the",
        "ellipsoids only: clustering and ellipsoid fitting are `fit_seconds`, so projection's full evaluation",
        "cost is eval + fit. The ray casters do all their work in `eval_seconds` (`fit_seconds` = 0).",
        "",
        "## Ratio, baseline over projection (same run)",
        "",
    ]
    out += _ratio_section(planners, models, col)
    out += ["", f"## Coverage at view {views} (last view)", ""]
    out += _coverage_section(outcomes, models, planners, runs, views)
    out += ["", "## Runs", ""]
    body = []
    for o in outcomes:
        final = o.rows[-1]["coverage"] if o.rows else None
        body.append(
            [
                o.label,
                o.planner,
                str(o.seed),
                str(len(o.rows)),
                "–" if final is None else f"{final:.4f}",
                o.terminated or "–",
                f"{o.seconds:.1f}",
                (o.error or o.reachable_error or "").replace("|", "\\|"),
            ]
        )
    header = ["model", "planner", "seed", "views", "final coverage", "wall s", "stopped", "error"]
    out += _table(header, [[*r[:5], r[6], r[5], r[7]] for r in body], left=2)
    return "\n".join(out) + "\n"


def _ratio_section(planners: Sequence[str], models: Sequence[str], col: Any) -> list[str]:
    if "projection" not in planners:
        return ["Projection did not take part in this bench: no ratio."]
    baselines = [p for p in planners if p != "projection"]
    if not baselines:
        return ["Only projection took part in this bench: no ratio."]
    p_eval, p_plan = _mean(col("projection", "eval_seconds")), _mean(col("projection", "plan_seconds"))
    p_fit = _mean(col("projection", "fit_seconds"))
    p_full = None if p_eval is None or p_fit is None else p_eval + p_fit
    body = [
        [
            b,
            _ratio(_mean(col(b, "eval_seconds")), p_eval),
            _ratio(_mean(col(b, "eval_seconds")), p_full),
            _ratio(_mean(col(b, "plan_seconds")), p_plan),
        ]
        for b in baselines
    ]
    header = ["baseline", "eval_seconds", "eval_seconds / projection's eval + fit", "plan_seconds"]
    lines = [
        "Mean per iteration over all models and seeds, baseline ÷ projection (> 1: projection is faster).",
        "",
        *_table(header, body),
        "",
        "Per model, ratio of mean `eval_seconds`:",
        "",
    ]
    body = [
        [b, *(_ratio(_mean(col(b, "eval_seconds", m)), _mean(col("projection", "eval_seconds", m))) for m in models)]
        for b in baselines
    ]
    return lines + _table(["baseline", *models], body)


def _coverage_section(
    outcomes: Sequence[RunOutcome],
    models: Sequence[str],
    planners: Sequence[str],
    runs: dict[tuple[str, str], list[RunOutcome]],
    views: int,
) -> list[str]:
    early = False
    body = []
    for p in planners:
        cells, finals = [], []
        for m in models:
            values = [float(o.rows[-1]["coverage"]) for o in runs[(m, p)] if o.rows[-1]["coverage"] is not None]
            finals.extend(values)
            short = any(len(o.rows) < views for o in runs[(m, p)])
            early |= short
            cells.append(_cell(values, 4) + ("*" if short else ""))
        body.append([p, *cells, _fmt(_mean(finals), 4)])
    ceiling = ceilings(outcomes)
    by_model = [[v for (m, _), v in ceiling.items() if m == model] for model in models]
    all_ceil = [v for vs in by_model for v in vs]
    body.append(["reachable (ceiling)", *(_cell(v, 4) for v in by_model), _fmt(_mean(all_ceil), 4)])
    lines = _table(["planner", *models, "mean"], body)
    lines += [
        "",
        "Coverage: the fraction of surface samples with a scanned point within 5 mm. The reachable ceiling",
        "is the union of every reachable candidate of one run's final hemisphere (projection's when it took",
        "part), computed once per (model, seed) and shared by all planners.",
    ]
    if early:
        lines.append(f"\n\\* stopped before view {views} (see Runs); its last coverage is shown.")
    return lines


# ---------------------------------------------------------------- plots


def _grid(n: int) -> tuple[int, int]:
    cols = min(n, 3)
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


def plot(out: Path, outcomes: Sequence[RunOutcome], models: Sequence[str], planners: Sequence[str]) -> None:
    """Write out/coverage.png (coverage against view, reachable ceiling dashed) and out/time.png
    (per iteration, log scale: plan time solid, evaluation incl. projection's fitting dotted); one panel per model.
    """
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure
    from matplotlib.ticker import MaxNLocator

    colors = {p: f"C{i % 10}" for i, p in enumerate(planners)}
    ceiling = ceilings(outcomes)
    nrows, ncols = _grid(max(1, len(models)))
    for name in ("coverage", "time"):
        fig = Figure(figsize=(4.2 * ncols, 3.4 * nrows), layout="constrained")
        FigureCanvasAgg(fig)
        axes = fig.subplots(nrows, ncols, squeeze=False).ravel()
        for k, (ax, model) in enumerate(zip(axes, models, strict=False)):
            for p in planners:
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
            if name == "coverage":
                values = [v for (m, _), v in ceiling.items() if m == model]
                if values:
                    ax.axhline(statistics.fmean(values), ls="--", color="0.4", label="reachable")
                ax.set_ylim(0.0, 1.02)
                ax.set_ylabel("coverage")
            else:
                ax.set_yscale("log")
                ax.set_ylabel("seconds per iteration")
            ax.set_title(model)
            ax.set_xlabel("view")
            ax.xaxis.set_major_locator(MaxNLocator(integer=True))
            ax.grid(True, alpha=0.3)
            if k == 0:
                ax.legend(fontsize="small", loc="lower right" if name == "coverage" else "best")
        for ax in axes[len(models) :]:
            ax.set_visible(False)
        title = "coverage against view" if name == "coverage" else "plan time (solid), candidate evaluation (dotted)"
        fig.suptitle(title)
        fig.savefig(out / f"{name}.png", dpi=110)


def write_report(out: Path, outcomes: Sequence[RunOutcome], meta: dict[str, Any]) -> None:
    """results.csv, runs.json, summary.md and the two plots."""
    write_results(out, outcomes)
    _atomic_write(out / "summary.md", summary_markdown(outcomes, meta))
    plot(out, outcomes, meta["models"], meta["planners"])
