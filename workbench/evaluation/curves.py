"""Metrics that separate planners: coverage against the ceiling, how fast it rises, paired comparisons.

Pure functions over numbers, no files and no runs:

- :func:`ratio_curve`: coverage / ceiling per view 1..N (a run that stopped early keeps its last value:
  the scan is over, its coverage no longer changes);
- :func:`area_under_curve`: the mean of that curve over views 1..N, in [0, 1] when coverage <= ceiling;
  a planner that gets there sooner scores higher even when every planner ends at the same coverage;
- :func:`views_to_reach`: the first view whose ratio is >= a threshold (N + 1 when never);
- :func:`mean_std` over seeds and placements;
- :func:`paired_comparison` of a planner against a reference planner over the same (model, seed,
  placement) triples: mean difference, its 95 % t-interval over the pairs, and wins / ties / losses.
"""

from __future__ import annotations

import math
import statistics
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from typing import TypeVar

K = TypeVar("K")

THRESHOLDS = (0.90, 0.95, 0.98)
"""Fractions of the ceiling for the views-to-reach columns (``views_to_90`` ...)."""


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


@dataclass(frozen=True)
class RunMetrics:
    """The ceiling-normalised metrics of one run."""

    final_ratio: float
    """coverage / ceiling at view N."""
    auc: float
    """Mean of coverage / ceiling over views 1..N."""
    views_to: tuple[int, ...]
    """Views to reach each of :data:`THRESHOLDS` of the ceiling (N + 1 when never)."""


def run_metrics(coverage: Sequence[float], ceiling: float, views: int) -> RunMetrics:
    """:class:`RunMetrics` of one run (see :func:`ratio_curve` for the arguments)."""
    curve = ratio_curve(coverage, ceiling, views)
    return RunMetrics(curve[-1], area_under_curve(curve), tuple(views_to_reach(curve, t) for t in THRESHOLDS))


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
    "views_to_90", "views_to_95", "views_to_98"}`` over the views taken so far (None without a ceiling or a
    view with a coverage).

    iterations: the session record's iterations (each with a ``coverage``, None without ground truth).
    """
    coverage = [float(c) for c in (it.get("coverage") for it in iterations) if isinstance(c, int | float)]
    out: dict[str, object] = {"ceiling": ceiling, "coverage_ratio": None, "auc": None}
    out |= {f"views_to_{round(100 * t)}": None for t in THRESHOLDS}
    if ceiling is None or not coverage:
        return out
    metrics = run_metrics(coverage, ceiling, len(coverage))
    out["coverage_ratio"] = ratio_curve(coverage, ceiling, len(coverage))
    out["auc"] = metrics.auc
    out |= {f"views_to_{round(100 * t)}": v for t, v in zip(THRESHOLDS, metrics.views_to, strict=True)}
    return out
