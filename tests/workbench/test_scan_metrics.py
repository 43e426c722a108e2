"""The ceiling-normalised bench metrics on hand-made numbers."""

from __future__ import annotations

import math

import pytest

from workbench.evaluation.curves import (
    THRESHOLDS,
    area_under_curve,
    mean_std,
    paired_comparison,
    ratio_curve,
    run_metrics,
    views_to_reach,
)


def test_ratio_curve_divides_and_extends_a_short_run() -> None:
    assert ratio_curve([0.4, 0.6], 0.8, 4) == pytest.approx([0.5, 0.75, 0.75, 0.75])
    assert ratio_curve([0.2, 0.4, 0.8], 0.8, 2) == pytest.approx([0.25, 0.5])


@pytest.mark.parametrize(
    ("args", "field"),
    [
        (([], 0.8, 3), "coverage"),
        (([0.5], 0.0, 3), "ceiling"),
        (([0.5], 0.8, 0), "views"),
        (([math.nan], 1.0, 1), "coverage"),
    ],
)
def test_ratio_curve_refuses_bad_input(args: tuple, field: str) -> None:
    with pytest.raises(ValueError, match=field):
        ratio_curve(*args)


def test_area_under_curve_is_the_mean_over_views() -> None:
    assert area_under_curve([0.5, 0.75, 1.0, 1.0]) == pytest.approx(0.8125)
    with pytest.raises(ValueError, match="curve"):
        area_under_curve([])


def test_views_to_reach_first_view_or_n_plus_one() -> None:
    curve = [0.5, 0.91, 0.96, 0.97]
    assert [views_to_reach(curve, t) for t in THRESHOLDS] == [2, 3, 5]
    assert views_to_reach([0.95], 0.95) == 1  # reaching the threshold exactly counts


def test_run_metrics_of_a_run_that_stopped_early() -> None:
    m = run_metrics([0.45, 0.855, 0.882], 0.9, 5)  # ratios 0.5, 0.95, 0.98 then held
    assert m.final_ratio == pytest.approx(0.98)
    assert m.auc == pytest.approx((0.5 + 0.95 + 0.98 * 3) / 5)
    assert m.views_to == (2, 2, 3)


def test_mean_std() -> None:
    assert mean_std([]) == (None, None)
    assert mean_std([2.0]) == (2.0, None)
    mean, std = mean_std([1.0, 2.0, 3.0, 6.0])
    assert mean == 3.0 and std == pytest.approx(math.sqrt(14 / 3))


def test_paired_comparison_interval_and_counts() -> None:
    ref = {("bunny", 0, 0.0): 0.5, ("bunny", 1, 0.0): 0.5, ("mug", 0, 0.0): 0.5, ("mug", 9, 0.0): 0.1}
    planner = {("bunny", 0, 0.0): 1.5, ("bunny", 1, 0.0): 2.5, ("mug", 0, 0.0): 3.5}  # diffs 1, 2, 3
    p = paired_comparison(planner, ref)
    assert p is not None
    assert p.n == 3 and p.mean == pytest.approx(2.0)
    half = 4.302652729911275 / math.sqrt(3)  # t(0.975, 2) * sd 1 / sqrt(3)
    assert p.low == pytest.approx(2.0 - half) and p.high == pytest.approx(2.0 + half)
    assert (p.wins, p.ties, p.losses) == (3, 0, 0)
    assert not p.significant  # three pairs: the interval still includes 0


def test_paired_comparison_lower_is_better_ties_and_one_pair() -> None:
    ref = {"a": 5, "b": 5, "c": 5, "d": 5}
    views = {"a": 3, "b": 5, "c": 6, "d": 3}
    p = paired_comparison(views, ref, higher_is_better=False)
    assert p is not None and (p.wins, p.ties, p.losses) == (2, 1, 1)
    close = paired_comparison({"a": 0.9005}, {"a": 0.9}, tie=0.001)
    assert close is not None and (close.wins, close.ties, close.losses) == (0, 1, 0)
    assert close.low is None and close.high is None and not close.significant
    assert paired_comparison({"a": 1.0}, {"b": 1.0}) is None


def test_a_clear_difference_is_significant() -> None:
    ref = {k: 0.80 + 0.001 * k for k in range(8)}
    planner = {k: v + 0.05 + 0.002 * (k % 2) for k, v in ref.items()}
    p = paired_comparison(planner, ref)
    assert p is not None and p.significant and p.low is not None and p.low > 0.04


def test_time_to_reach_is_the_cumulative_robot_time_or_a_penalty() -> None:
    from workbench.evaluation import TIME_THRESHOLDS, cumulative_seconds, time_to_reach
    from workbench.evaluation.curves import ceiling_metrics

    seconds = [0.5, 3.0, 4.0, 2.5]
    assert cumulative_seconds(seconds) == [0.5, 3.5, 7.5, 10.0]
    ratios = [0.4, 0.91, 0.94, 0.96]
    assert [time_to_reach(ratios, seconds, t) for t in TIME_THRESHOLDS] == [3.5, 10.0]
    assert time_to_reach(ratios, seconds, 0.99) == pytest.approx(12.5)  # never: 10 s + one more view of 2.5 s
    with pytest.raises(ValueError, match=r"^ratios, seconds: need the same number"):
        time_to_reach(ratios, seconds[:2], 0.9)
    with pytest.raises(ValueError, match=r"^seconds: must be finite"):
        cumulative_seconds([1.0, -2.0])
    # the session's metrics: the times when every view has its robot seconds, None otherwise
    its: list[dict[str, float | None]] = [
        {"coverage": 0.9 * r, "robot_seconds": s} for r, s in zip(ratios, seconds, strict=True)
    ]
    m = ceiling_metrics(its, 0.9)
    assert m["time_to_90"] == pytest.approx(3.5) and m["time_to_95"] == pytest.approx(10.0)
    assert m["robot_seconds"] == pytest.approx([0.5, 3.5, 7.5, 10.0])
    its[1]["robot_seconds"] = None
    assert ceiling_metrics(its, 0.9)["time_to_95"] is None
