"""summary.md of ``nbv bench``: the ceiling-normalised metrics and paired comparisons, then the paper's
Table I shape (planning time), evaluation time and ratios, coverage at the last view and the runs.

The numbers come from :mod:`nbv.bench_metrics`; :func:`run_metrics_of` gives them per run.
"""

from __future__ import annotations

import statistics
from collections import defaultdict
from collections.abc import Mapping, Sequence
from typing import Any

from workbench.evaluation import (
    THRESHOLDS,
    TIME_THRESHOLDS,
    Paired,
    RunMetrics,
    RunOutcome,
    mean_std,
    move_points,
    paired_comparison,
    run_metrics,
)

Row = dict[str, Any]

TIE = 0.001
"""Paired comparisons of coverage / ceiling and its area: a difference within 0.1 point is a tie."""

RunKey = tuple[str, str, int, float]
"""(model, planner, seed, yaw)."""


def run_metrics_of(
    outcomes: Sequence[RunOutcome], ceilings: Mapping[tuple[str, float], float], views: int
) -> dict[RunKey, RunMetrics]:
    """The ceiling-normalised metrics of every finished run whose (model, yaw) has a ceiling > 0."""
    out: dict[RunKey, RunMetrics] = {}
    for o in outcomes:
        ceiling = ceilings.get(o.ceiling_key)
        rows = [r for r in o.rows if r["coverage"] is not None]
        coverage = [r["coverage"] for r in rows]
        seconds = [r.get("robot_seconds") for r in rows]
        timed = [float(s) for s in seconds if isinstance(s, int | float)]  # runs of older benches lack it
        if o.error is None and coverage and ceiling:
            robot = timed if len(timed) == len(coverage) else None
            moves = [move_points(r.get("move_coverage")) for r in rows]
            out[(o.label, o.planner, o.seed, o.yaw)] = run_metrics(coverage, ceiling, views, robot, moves)
    return out


def _pm(values: Sequence[float], digits: int) -> str:
    mean, std = mean_std(values)
    if mean is None:
        return "–"
    return f"{mean:.{digits}f}" + ("" if std is None else f" ± {std:.{digits}f}")


def _interval(p: Paired, digits: int) -> str:
    if p.low is None or p.high is None:
        return "–"
    return f"[{p.low:+.{digits}f}, {p.high:+.{digits}f}]" + (" *" if p.significant else "")


METRICS: tuple[tuple[str, str, bool, float, int], ...] = (
    ("final", "coverage / ceiling at the last view", True, TIE, 4),
    ("auc", "area under coverage / ceiling (mean over views)", True, TIE, 4),
    ("v95", "views to 95 % of the ceiling", False, 0.0, 2),
    ("t90", "robot seconds to 90 % of the ceiling", False, 0.0, 2),
    ("t95", "robot seconds to 95 % of the ceiling", False, 0.0, 2),
)
"""(key, label, higher is better, tie tolerance, digits) of the paired comparisons."""


FSCORES = (("fscore_5mm", "F@5mm at the last view"), ("surface_fscore_5mm", "surface F@5mm at the last view"))
"""The accuracy rows of the paired comparisons: (results.csv column, label): the cloud's F-score at 5 mm
(``workbench.evaluation``) and the reconstructed surface's (``workbench.surface``)."""


def final_fscores(
    outcomes: Sequence[RunOutcome], planner: str, column: str = "fscore_5mm"
) -> dict[tuple[str, int, float], float]:
    """(model, seed, yaw) -> ``column`` (an F-score) at the last view of ``planner``'s finished runs (runs
    without one left out)."""
    out: dict[tuple[str, int, float], float] = {}
    for o in outcomes:
        if o.planner == planner and o.error is None and o.rows and o.rows[-1].get(column) is not None:
            out[o.key] = float(o.rows[-1][column])
    return out


def _metric(m: RunMetrics, key: str) -> float | None:
    """The run's value of a :data:`METRICS` key (None: a robot time the run does not have)."""
    if key.startswith("t"):
        k = TIME_THRESHOLDS.index(int(key[1:]) / 100)
        return m.time_to[k] if len(m.time_to) > k else None
    return {"final": m.final_ratio, "auc": m.auc, "v95": float(m.views_to[THRESHOLDS.index(0.95)])}[key]


def ceiling_sections(
    ok: Sequence[RunOutcome],
    models: Sequence[str],
    planners: Sequence[str],
    reference: str,
    views: int,
    ceilings: Mapping[tuple[str, float], float],
) -> list[str]:
    """The markdown of "Coverage against the ceiling" and "Paired comparison against <reference>"."""
    metrics = run_metrics_of(ok, ceilings, views)
    lines = ["## Coverage against the ceiling", ""]
    if not metrics:
        note = "No ceiling was computed (`--no-reachable`, or it failed): no normalised metrics."
        return [*lines, note, "", f"## Paired comparison against {reference}", "", note]
    head = ["planner", f"at view {views}", "area under curve", *(f"views to {round(t * 100)} %" for t in THRESHOLDS)]
    head += [f"robot s to {round(t * 100)} %" for t in TIME_THRESHOLDS]
    body = []
    for p in planners:
        ms = [m for (_, q, _, _), m in metrics.items() if q == p]
        cells = [_pm([m.final_ratio for m in ms], 4), _pm([m.auc for m in ms], 4)]
        cells += [_pm([float(m.views_to[i]) for m in ms], 2) for i in range(len(THRESHOLDS))]
        cells += [_pm([m.time_to[i] for m in ms if len(m.time_to) > i], 1) for i in range(len(TIME_THRESHOLDS))]
        body.append([p, *cells])
    lines += _table(head, body)
    lines += [
        "",
        "Coverage divided by the object's reachable ceiling, mean ± standard deviation over models, seeds and",
        "placements. The area under the curve is the mean of coverage / ceiling over views 1..N: it rewards a",
        f"planner that gets there sooner. Views to reach a fraction of the ceiling count {views + 1} when never.",
        "Robot seconds to reach a fraction of the ceiling: the cumulative robot time (moves, plate turns,",
        "captures, planning) at the first view that reaches it; when never, the run's total plus its mean per",
        "view (one more view).",
        "",
        "Area under the curve per model:",
        "",
    ]
    body = []
    for p in planners:
        body.append(
            [
                p,
                *(
                    _pm([m.auc for (mm, q, _, _), m in metrics.items() if q == p and mm == model], 4)
                    for model in models
                ),
            ]
        )
    lines += _table(["planner", *models], body)
    lines += ["", f"## Paired comparison against {reference}", ""]
    others = [p for p in planners if p != reference]
    if not others:
        return [*lines, f"Only {reference} took part: nothing to compare.", ""]
    head = ["planner", "metric", "pairs", "mean difference", "95 % interval", "wins / ties / losses"]
    body = []
    for p in others:
        for key, label, higher, tie, digits in METRICS:
            mine = {
                (m, s, y): x for (m, q, s, y), v in metrics.items() if q == p and (x := _metric(v, key)) is not None
            }
            ref = {
                (m, s, y): x
                for (m, q, s, y), v in metrics.items()
                if q == reference and (x := _metric(v, key)) is not None
            }
            c = paired_comparison(mine, ref, higher_is_better=higher, tie=tie)
            if c is None:
                body.append([p, label, "0", "–", "–", "–"])
                continue
            body.append(
                [p, label, str(c.n), f"{c.mean:+.{digits}f}", _interval(c, digits), f"{c.wins} / {c.ties} / {c.losses}"]
            )
        for column, label in FSCORES:
            mine_f, ref_f = final_fscores(ok, p, column), final_fscores(ok, reference, column)
            c = paired_comparison(mine_f, ref_f, higher_is_better=True, tie=TIE)
            if c is None:
                body.append([p, label, "0", "–", "–", "–"])
            else:
                body.append(
                    [p, label, str(c.n), f"{c.mean:+.4f}", _interval(c, 4), f"{c.wins} / {c.ties} / {c.losses}"]
                )
    lines += _table(head, body, left=2)
    lines += [
        "",
        f"Each pair is one (model, seed, placement) scanned by the planner and by {reference}; the difference is",
        f"planner − {reference}. The interval is the 95 % t-interval of the mean difference over the pairs; * marks",
        "one that excludes 0 (a difference larger than the seed-to-seed noise). A win is a better value: higher",
        f"coverage, fewer views, less robot time; coverage differences within {TIE} are ties.",
    ]
    return lines


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


def summary_markdown(
    outcomes: Sequence[RunOutcome], meta: dict[str, Any], ceilings: Mapping[tuple[str, float], float] | None = None
) -> str:
    """summary.md: coverage against the ceiling and the paired comparisons first, then Table I (total
    planning time), evaluation time and ratios, coverage at the last view, runs.

    ceilings: (model, yaw) -> reachable-coverage ceiling (missing: no ceiling-normalised metrics)."""
    ceilings = ceilings or {}
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
    yaws = meta.get("yaws", [0.0])
    executor = meta.get("executor", f"{meta['jobs']} job(s)")
    out = [
        "# nbv bench",
        "",
        f"Models: {', '.join(models)}. Planners: {', '.join(planners)}. Views: {views}. "
        f"Seeds: {', '.join(map(str, meta['seeds']))}. Placements (yaw, degrees): {', '.join(f'{y:g}' for y in yaws)}. "
        f"Resolution {meta['resolution']} m, {meta['candidates']} candidates. Executor: {executor}"
        + (f" ({threads} BLAS thread(s) per run)" if threads else " (inline)")
        + f"; wall time {meta['wall_seconds']:.1f} s"
        + (f", of which ceilings {meta['ceiling_seconds']:.1f} s." if "ceiling_seconds" in meta else "."),
        "",
        "Every planner of a (model, placement, seed) starts from the same view with the same seed for camera",
        "noise. With several jobs or workers runs share the CPUs: ratios compare planners under the same load;",
        "for absolute times use `--jobs 1`.",
        "",
    ]
    out += ceiling_sections(ok, models, planners, meta.get("reference", planners[0]), views, ceilings)
    out += [
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
        per_view = [float(r.get("robot_seconds") or 0.0) for r in rows[p]]  # runs of older benches lack it
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
    out += _coverage_section(models, planners, runs, views, ceilings)
    out += ["", "## Runs", ""]
    body = []
    for o in outcomes:
        final = o.rows[-1]["coverage"] if o.rows else None
        body.append(
            [
                o.label,
                o.planner,
                f"{o.seed} / {o.yaw:g}",
                str(len(o.rows)),
                "–" if final is None else f"{final:.4f}",
                o.terminated or "–",
                f"{o.seconds:.1f}",
                (o.error or "").replace("|", "\\|"),
            ]
        )
    header = ["model", "planner", "seed / yaw", "views", "final coverage", "wall s", "stopped", "error"]
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
    models: Sequence[str],
    planners: Sequence[str],
    runs: dict[tuple[str, str], list[RunOutcome]],
    views: int,
    ceilings: Mapping[tuple[str, float], float],
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
    by_model = [[v for (m, _), v in ceilings.items() if m == model] for model in models]
    all_ceil = [v for vs in by_model for v in vs]
    body.append(["reachable (ceiling)", *(_cell(v, 4) for v in by_model), _fmt(_mean(all_ceil), 4)])
    lines = _table(["planner", *models, "mean"], body)
    lines += [
        "",
        "Coverage: the fraction of surface samples with a scanned point within 5 mm. The reachable ceiling",
        "is the union of every reachable candidate of the hemisphere about the object's true bounding box,",
        "computed once per (model, placement) and shared by all planners and seeds (the row shows the mean",
        "over placements).",
    ]
    if early:
        lines.append(f"\n\\* stopped before view {views} (see Runs); its last coverage is shown.")
    return lines
