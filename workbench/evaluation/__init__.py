"""How good a scan is, measured against a ground truth, and the headless scan the bench and ``nbv scan`` run.

- accuracy.py: GroundTruth, Accuracy, accuracy: precision, recall and F at 2 and 5 mm, distances, chamfer; the
  coverage taken from the recall when both are asked of one cloud (coverage_and_accuracy);
- coverage.py: ground-truth coverage (the fraction of surface samples a cloud point is near);
- curves.py: coverage against the ceiling per view, its area, views-to-X, robot time to X, means and paired
  comparisons;
- ceiling.py: the reachable-coverage ceiling by visibility (one occlusion ray per sample and view) and by
  rendering (the reference; the samples one rendered view covers: ``view_coverage``);
- object_ceiling.py: the ceiling of one (mesh, placement, cell), keyed and cached on disk;
- ceiling_service.py: a session's ceiling computed in a worker process, one at a time;
- scan.py: Algorithm 1 headless (``run_scan``), with metrics per iteration;
- simulate.py: one simulated scan of a model (load, place, build the cell, run, measure);
- runs.py: one run of a bench (RunTask) and what it gave (RunOutcome), picklable;
- executors.py: running many of them, in local processes (forkserver) or on a Dask cluster.
"""

from workbench.evaluation.accuracy import (
    ACCURACY_COLUMNS,
    TAUS_MM,
    Accuracy,
    GroundTruth,
    accuracy,
    coverage_and_accuracy,
    fscore,
)
from workbench.evaluation.ceiling import DEFAULT_CEILING, CeilingConfig, view_coverage
from workbench.evaluation.coverage import coverage
from workbench.evaluation.curves import (
    THRESHOLDS,
    TIME_THRESHOLDS,
    Paired,
    RunMetrics,
    area_under_curve,
    cumulative_seconds,
    mean_std,
    move_points,
    paired_comparison,
    ratio_curve,
    run_metrics,
    time_to_reach,
    views_to_reach,
)
from workbench.evaluation.executors import execute, one_line, run_dask, run_local
from workbench.evaluation.object_ceiling import Ceiling, cached_ceiling, ceiling_mask, object_ceiling, reference_mask
from workbench.evaluation.recorded import (
    ORACLE,
    PointTruth,
    RecordedBench,
    RecordedRun,
    bench_recorded,
    fewest_views,
    greedy_order,
    recorded_truth,
    run_recorded,
    view_cover,
)
from workbench.evaluation.runs import MeshPayload, RunOutcome, RunTask
from workbench.evaluation.scan import (
    PLAN_STAGES,
    STAGES,
    IterationRecord,
    ScanResult,
    final_accuracy,
    icp_rejections,
    make_record,
    run_scan,
)
from workbench.evaluation.simulate import SimScan, simulate

__all__ = [
    "ACCURACY_COLUMNS",
    "DEFAULT_CEILING",
    "ORACLE",
    "PLAN_STAGES",
    "STAGES",
    "TAUS_MM",
    "THRESHOLDS",
    "TIME_THRESHOLDS",
    "Accuracy",
    "Ceiling",
    "CeilingConfig",
    "GroundTruth",
    "IterationRecord",
    "MeshPayload",
    "Paired",
    "PointTruth",
    "RecordedBench",
    "RecordedRun",
    "RunMetrics",
    "RunOutcome",
    "RunTask",
    "ScanResult",
    "SimScan",
    "accuracy",
    "area_under_curve",
    "bench_recorded",
    "cached_ceiling",
    "ceiling_mask",
    "coverage",
    "coverage_and_accuracy",
    "cumulative_seconds",
    "execute",
    "fewest_views",
    "final_accuracy",
    "fscore",
    "greedy_order",
    "icp_rejections",
    "make_record",
    "mean_std",
    "move_points",
    "object_ceiling",
    "one_line",
    "paired_comparison",
    "ratio_curve",
    "recorded_truth",
    "reference_mask",
    "run_dask",
    "run_local",
    "run_metrics",
    "run_recorded",
    "run_scan",
    "simulate",
    "time_to_reach",
    "view_cover",
    "view_coverage",
    "views_to_reach",
]
