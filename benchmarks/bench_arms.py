"""The arms table of docs/experiments/arms.md from an ``nbv bench --arms ...`` results.csv.

    python benchmarks/bench_arms.py out/arms/results.csv

Per arm: the mean final coverage, mean coverage / ceiling, mean AUC, robot time to 95 % of the arm's own ceiling
(median over the runs that get there, and how many do), the median plan time per view and its ratio to the first
arm's (the reference, the UR5 when it is listed first), and per-run plan times as a series.
"""

from __future__ import annotations

import csv
import statistics
import sys
from collections import defaultdict


def main(path: str) -> None:
    runs: dict[str, dict[str, list[dict[str, str]]]] = defaultdict(lambda: defaultdict(list))
    order: list[str] = []
    with open(path) as fh:
        for row in csv.DictReader(fh):
            arm = row["arm"]
            if arm not in order:
                order.append(arm)
            runs[arm][row["model"]].append(row)
    plan_median: dict[str, float] = {}
    print(
        "| arm | runs | final coverage | coverage / ceiling | AUC | robot time to 95 % (s, median) | reach 95 % | "
        "plan time per view (s, median) | vs the first |"
    )
    print("|---|---|---|---|---|---|---|---|---|")
    for arm in order:
        models = runs[arm]
        finals = [rows[-1] for rows in models.values()]
        cov = statistics.mean(float(r["coverage"]) for r in finals)
        ratio = [float(r["coverage_ratio"]) for r in finals if r["coverage_ratio"]]
        auc = [float(r["auc"]) for r in finals if r["auc"]]
        t95 = [float(r["time_to_95"]) for r in finals if r["time_to_95"]]
        plans = [float(r["plan_seconds"]) for rows in models.values() for r in rows]
        plan_median[arm] = statistics.median(plans)
        ref = plan_median[order[0]]
        print(
            f"| {arm} | {len(finals)} | {cov:.4f} | {statistics.mean(ratio):.4f} | {statistics.mean(auc):.4f} | "
            f"{statistics.median(t95):.1f} | {len(t95)} of {len(finals)} | {plan_median[arm]:.3f} | "
            f"{plan_median[arm] / ref:.2f}x |"
        )
    print()
    print("plan time per view, median per run (s), in model order:")
    for arm in order:
        series = [statistics.median(float(r["plan_seconds"]) for r in rows) for rows in runs[arm].values()]
        print(f"  {arm}: " + " ".join(f"{v:.2f}" for v in series))


if __name__ == "__main__":
    main(sys.argv[1] if len(sys.argv) > 1 else "out/arms/results.csv")
