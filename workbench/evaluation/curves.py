"""Metrics that separate planners: coverage against the ceiling, how fast it rises, paired comparisons.

Pure functions over numbers, no files and no runs:

- :func:`ratio_curve`: coverage / ceiling per view 1..N (a run that stopped early keeps its last value:
  the scan is over, its coverage no longer changes);
- :func:`area_under_curve`: the mean of that curve over views 1..N, in [0, 1] when coverage <= ceiling;
  a planner that gets there sooner scores higher even when every planner ends at the same coverage;
- :func:`views_to_reach`: the first view whose ratio is >= a threshold (N + 1 when never);
- :func:`cumulative_seconds` and :func:`time_to_reach`: robot time to coverage, the cumulative robot seconds
  (moves, plate turns, captures, planning) at the first view whose ratio is >= a threshold; when the run never
  gets there, its total robot seconds plus its mean seconds per view (the time of one more view, as
  views-to-reach counts N + 1);
- :func:`mean_std` over seeds and placements;
- :func:`paired_comparison` of a planner against a reference planner over the same (model, seed,
  placement) triples: mean difference, its 95 % t-interval over the pairs, and wins / ties / losses.
"""

from __future__ import annotations

import json
import math
import statistics
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from typing import TypeVar

K = TypeVar("K")

THRESHOLDS = (0.90, 0.95, 0.98)
"""Fractions of the ceiling for the views-to-reach columns (``views_to_90`` ...)."""
TIME_THRESHOLDS = (0.90, 0.95)
"""Fractions of the ceiling for the robot-time-to-reach columns (``time_to_90``, ``time_to_95``)."""


def ratio_curve(coverage: Sequence[float], ceiling: float, views: int) -> list[float]:
    """(views,) coverage / ceiling at views 1..``views``.

    coverage: the run's coverage after each view (at least one value, in view order).
    ceiling: the reachable-coverage ceiling, > 0. A run shorter than ``views`` is extended with its
    last value; a longer one is cut. ValueError (naming the argument) on bad input.
    """
    if not coverage:
        raise ValueError("coverage: need at least one view")
    if not (math.isfinite(ceiling) and ceiling > 0):
        raise ValueError(f"ceiling: must be > 0, got {ceiling!r}")
    if not (isinstance(views, int) and views >= 1):
        raise ValueError(f"views: must be an integer >= 1, got {views!r}")
    values = [float(c) for c in coverage[:views]]
    if not all(math.isfinite(v) for v in values):
        raise ValueError("coverage: non-finite value")
    values += [values[-1]] * (views - len(values))
    return [v / ceiling for v in values]


def area_under_curve(curve: Sequence[float]) -> float:
    """The mean of ``curve`` (coverage / ceiling at views 1..N): the area under it with unit view steps, / N."""
    if not curve:
        raise ValueError("curve: need at least one view")
    return statistics.fmean(curve)


def views_to_reach(curve: Sequence[float], threshold: float) -> int:
    """The first view (1-based) at which ``curve`` >= ``threshold``; ``len(curve) + 1`` when it never does."""
    for view, value in enumerate(curve, start=1):
        if value >= threshold - 1e-12:
            return view
    return len(curve) + 1


def cumulative_seconds(seconds: Sequence[float]) -> list[float]:
    """(n,) the running sum of per-view robot ``seconds`` (n,): the robot time when each view's plan is done."""
    out, total = [], 0.0
    for s in seconds:
        value = float(s)
        if not (math.isfinite(value) and value >= 0):
            raise ValueError(f"seconds: must be finite and >= 0, got {s!r}")
        total += value
        out.append(total)
    return out


MovePoints = Sequence[Sequence[tuple[float, float]]]
"""Per view taken, the (t, value) of each frame integrated during the move to it (t: seconds since that move
started; value: coverage / ceiling, or coverage before :func:`run_metrics` divides it)."""


def time_to_reach(
    ratios: Sequence[float], seconds: Sequence[float], threshold: float, moves: MovePoints | None = None
) -> float:
    """Cumulative robot seconds at the first view whose coverage / ceiling (``ratios`` (n,), the views actually
    taken) is >= ``threshold``; ``seconds`` (n,) the robot seconds of each view. Never reached: the total plus the
    mean per view (documented penalty: one more view). ValueError for no view or lengths that differ.
    moves: capture during moves: (n,) per view the (t, ratio) of the frames taken on the way to it; a frame counts
    at its time, the robot seconds before its view's move plus t (the move comes first in a view's seconds)."""
    if not ratios or len(ratios) != len(seconds):
        raise ValueError(f"ratios, seconds: need the same number (>= 1) of views, got {len(ratios)} and {len(seconds)}")
    if moves is not None and len(moves) != len(ratios):
        raise ValueError(f"moves: need one list per view ({len(ratios)}), got {len(moves)}")
    cumulative = cumulative_seconds(seconds)
    for i, (ratio, t) in enumerate(zip(ratios, cumulative, strict=True)):
        before = cumulative[i - 1] if i > 0 else 0.0
        for t_move, move_ratio in moves[i] if moves is not None else ():
            if move_ratio >= threshold - 1e-12:
                return before + min(float(t_move), float(seconds[i]))
        if ratio >= threshold - 1e-12:
            return t
    return cumulative[-1] * (1.0 + 1.0 / len(cumulative))


@dataclass(frozen=True)
class RunMetrics:
    """The ceiling-normalised metrics of one run."""

    final_ratio: float
    """coverage / ceiling at view N."""
    auc: float
    """Mean of coverage / ceiling over views 1..N."""
    views_to: tuple[int, ...]
    """Views to reach each of :data:`THRESHOLDS` of the ceiling (N + 1 when never)."""
    time_to: tuple[float, ...] = ()
    """Robot seconds to reach each of :data:`TIME_THRESHOLDS` of the ceiling (:func:`time_to_reach`); empty when
    the run's robot seconds are not known."""


def run_metrics(
    coverage: Sequence[float],
    ceiling: float,
    views: int,
    robot_seconds: Sequence[float] | None = None,
    move_coverage: MovePoints | None = None,
) -> RunMetrics:
    """:class:`RunMetrics` of one run (see :func:`ratio_curve` for the arguments; ``robot_seconds``: (n,) per
    view taken, for the robot time to coverage; ``move_coverage``: (n,) per view the (t, coverage) of the frames
    taken on the way to it, counted at their times in the robot time to coverage)."""
    curve = ratio_curve(coverage, ceiling, views)
    time_to: tuple[float, ...] = ()
    if robot_seconds is not None:
        taken = [float(c) / ceiling for c in coverage]
        moves = None
        if move_coverage is not None:
            moves = [[(float(t), float(c) / ceiling) for t, c in points] for points in move_coverage]
        time_to = tuple(time_to_reach(taken, robot_seconds, t, moves) for t in TIME_THRESHOLDS)
    return RunMetrics(curve[-1], area_under_curve(curve), tuple(views_to_reach(curve, t) for t in THRESHOLDS), time_to)


def mean_std(values: Sequence[float]) -> tuple[float | None, float | None]:
    """(mean, sample standard deviation); (None, None) for no values, std None for one value."""
    if not values:
        return None, None
    mean = statistics.fmean(values)
    return mean, (statistics.stdev(values) if len(values) > 1 else None)


def t_quantile(p: float, dof: int) -> float:
    """The ``p`` quantile of Student's t with ``dof`` >= 1 degrees of freedom."""
    from scipy.stats import t

    return float(t.ppf(p, dof))


@dataclass(frozen=True)
class Paired:
    """A planner against the reference over the same (model, seed, placement) pairs: planner - reference."""

    n: int
    """Pairs."""
    mean: float
    """Mean difference."""
    low: float | None
    """Lower end of the 95 % t-interval of the mean difference (None with one pair)."""
    high: float | None
    """Upper end (None with one pair)."""
    wins: int
    """Pairs where the planner is better by more than the tie tolerance."""
    ties: int
    losses: int

    @property
    def significant(self) -> bool:
        """The 95 % interval excludes 0."""
        return self.low is not None and self.high is not None and (self.low > 0 or self.high < 0)


def paired_comparison(
    planner: Mapping[K, float],
    reference: Mapping[K, float],
    *,
    higher_is_better: bool = True,
    tie: float = 0.0,
) -> Paired | None:
    """Compare ``planner`` with ``reference`` over the keys both have (e.g. (model, seed, yaw)).

    A pair is a tie when ``|difference| <= tie``; otherwise a win when the planner is better
    (higher, or lower with ``higher_is_better=False``). None when no key is shared.
    """
    keys = [k for k in planner if k in reference]
    if not keys:
        return None
    diffs = [float(planner[k]) - float(reference[k]) for k in keys]
    n = len(diffs)
    mean = statistics.fmean(diffs)
    low = high = None
    if n > 1:
        half = t_quantile(0.975, n - 1) * statistics.stdev(diffs) / math.sqrt(n)
        low, high = mean - half, mean + half
    sign = 1.0 if higher_is_better else -1.0
    wins = sum(1 for d in diffs if sign * d > tie)
    losses = sum(1 for d in diffs if sign * d < -tie)
    return Paired(n, mean, low, high, wins, n - wins - losses, losses)


def ceiling_metrics(iterations: Sequence[Mapping[str, object]], ceiling: float | None) -> dict[str, object]:
    """What a session reports against its ceiling: ``{"ceiling", "coverage_ratio": [...] per view, "auc",
    "views_to_90", "views_to_95", "views_to_98", "robot_seconds": [...] cumulative per view, "time_to_90",
    "time_to_95"}`` over the views taken so far (None without a ceiling or a view with a coverage; the robot
    times also None unless every view has its ``robot_seconds``).

    iterations: the session record's iterations (each with a ``coverage``, None without ground truth, and
    ``robot_seconds``: the view's move, capture and plan seconds).
    """
    coverage = [float(c) for c in (it.get("coverage") for it in iterations) if isinstance(c, int | float)]
    seconds = [s for s in (it.get("robot_seconds") for it in iterations) if isinstance(s, int | float)]
    out: dict[str, object] = {"ceiling": ceiling, "coverage_ratio": None, "auc": None, "robot_seconds": None}
    out |= {f"views_to_{round(100 * t)}": None for t in THRESHOLDS}
    out |= {f"time_to_{round(100 * t)}": None for t in TIME_THRESHOLDS}
    if len(seconds) == len(iterations) and seconds:
        out["robot_seconds"] = cumulative_seconds(seconds)
    if ceiling is None or not coverage:
        return out
    timed = len(seconds) == len(coverage) == len(iterations)
    metrics = run_metrics(coverage, ceiling, len(coverage), seconds if timed else None)
    out["coverage_ratio"] = ratio_curve(coverage, ceiling, len(coverage))
    out["auc"] = metrics.auc
    out |= {f"views_to_{round(100 * t)}": v for t, v in zip(THRESHOLDS, metrics.views_to, strict=True)}
    out |= {f"time_to_{round(100 * t)}": v for t, v in zip(TIME_THRESHOLDS, metrics.time_to, strict=False)}
    return out


def move_points(cell: object) -> list[tuple[float, float]]:
    """The (t, coverage) of a row's move frames from its ``move_coverage`` column (a JSON list; empty or missing in
    runs without capture during moves and in older benches)."""
    if isinstance(cell, list):
        values = cell
    elif isinstance(cell, str) and cell.strip():
        values = json.loads(cell)
    else:
        return []
    return [(float(t), float(c)) for t, c in values]
