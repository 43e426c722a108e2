"""``nbv bench --recorded DIR``: the planners choosing among a recorded set's views, against the oracle."""

from __future__ import annotations

import argparse
import json
from pathlib import Path
from typing import Any

from nbv.options import CliError, planner_config_from_args


def planner_names(text: str) -> list[str]:
    """``--planners`` for a recorded set: any planner, and ``oracle``. CliError for an unknown or repeated name."""
    from planner.evaluators import evaluator_names
    from workbench.evaluation import ORACLE

    names = [n.strip() for n in text.split(",") if n.strip()]
    known = [*evaluator_names(), ORACLE]
    if not names:
        raise CliError("--planners: give at least one planner")
    for i, name in enumerate(names):
        if name not in known:
            raise CliError(f"--planners: unknown planner {name!r} (known: {', '.join(known)})")
        if name in names[:i]:
            raise CliError(f"--planners: {name!r} is listed twice")
    return names


def load(path: Path, mesh: Path | None) -> Any:
    """The recorded set at ``path`` (CliError naming the option for anything unreadable)."""
    from devices.recorded import read_recorded

    if not path.is_dir():
        raise CliError(f"--recorded: {path} is not a folder")
    if mesh is not None and not mesh.is_file():
        raise CliError(f"--recorded-mesh: {mesh} is not a file")
    try:
        return read_recorded(path, reference=mesh)
    except ValueError as exc:
        raise CliError(f"--recorded: {exc}") from None


def run_recorded_bench(args: argparse.Namespace) -> int:
    """Run the planners on the recorded set, print the table, write results.json and summary.md to ``--out``."""
    from workbench.evaluation import bench_recorded

    if args.models:
        raise CliError("--recorded: give it instead of --models, not with them")
    if args.seeds < 1:
        raise CliError(f"--seeds: must be >= 1, got {args.seeds}")
    planners = planner_names(args.planners)
    recorded = load(args.recorded, args.recorded_mesh)
    config = planner_config_from_args(args)
    out: Path = args.out
    out.mkdir(parents=True, exist_ok=True)
    print(f"{recorded.name}: {len(recorded.views)} recorded views; planners {', '.join(planners)}", flush=True)

    def show(row: dict[str, Any]) -> None:
        print(
            f"  {row['planner']} seed {row['seed']}: views to 95 % {row['views_to_95']}, AUC {row['auc']:.3f}, "
            f"F@5mm {row['final_fscore_5mm']:.3f}; order {' '.join(row['order'])}",
            flush=True,
        )

    bench = bench_recorded(
        recorded, planners, config, seeds=args.seeds, surface=not getattr(args, "no_surface", False), on_run=show
    )
    head = (
        f"recorded ceiling: coverage {bench.ceiling:.4f} (all {bench.views} views through the pipeline); "
        f"fewest views to 95 % by brute force: {bench.fewest[0] if bench.fewest else '-'}"
    )
    print(head)
    print(bench.table())
    doc = {
        "set": recorded.name,
        "source": recorded.source,
        "views": bench.views,
        "ceiling": bench.ceiling,
        "ceiling_fscore_5mm": bench.ceiling_fscore,
        "ceiling_surface_fscore_5mm": bench.ceiling_surface_fscore,
        "fewest_views_to_95": None if bench.fewest is None else {"views": bench.fewest[0], "set": bench.fewest[1]},
        "runs": bench.rows,
        "summary": bench.summary(),
    }
    (out / "results.json").write_text(json.dumps(doc, indent=1))
    (out / "summary.md").write_text(f"# {recorded.name}\n\n{head}\n\n{bench.table()}\n")
    print(f"wrote {out}/results.json, {out}/summary.md")
    return 0


def scan_recorded(args: argparse.Namespace) -> dict[str, Any]:
    """``nbv scan --recorded DIR``: ``--planner`` (or ``oracle``) chooses among the set's views; prints a row per
    view and writes metrics.json, cloud.ply (and surface.ply) to ``--out``. Returns the metrics document."""
    from devices.ply import write_ply
    from workbench.evaluation import ORACLE, greedy_order, recorded_truth, run_recorded, view_cover

    planner = planner_names(args.planner)[0]
    recorded = load(args.recorded, None)
    config = planner_config_from_args(args)
    out: Path = args.out
    out.mkdir(parents=True, exist_ok=True)
    truth = recorded_truth(recorded)
    views = len(recorded.views)
    order = greedy_order(view_cover(recorded, truth), first=0) if planner == ORACLE else None
    ceiling = run_recorded(recorded, "all views", config, truth, order=list(range(views)), surface=False).coverage[-1]
    run = run_recorded(recorded, planner, config, truth, order=order, seed=int(args.seed or 0))
    print(f"{recorded.name}: {views} recorded views, planner {planner}; recorded ceiling {ceiling:.4f}")
    print(f"{'view':>4} {'name':>12} {'coverage':>8} {'precision':>9} {'F@5mm':>7}")
    for i, (name, c, p, f) in enumerate(zip(run.order, run.coverage, run.precision, run.fscore, strict=True)):
        print(f"{i:>4} {name:>12} {c:>8.4f} {p:>9.4f} {f:>7.4f}")
    doc = {"set": recorded.name, "source": recorded.source, "ceiling": ceiling, **run.metrics(ceiling, views)}
    doc["iterations"] = [
        {"view": name, "coverage": c, "precision_5mm": p, "fscore_5mm": f}
        for name, c, p, f in zip(run.order, run.coverage, run.precision, run.fscore, strict=True)
    ]
    (out / "metrics.json").write_text(json.dumps(doc, indent=1))
    write_ply(out / "cloud.ply", run.cloud)
    surface = "" if run.surface_fscore is None else f", surface F@5mm {run.surface_fscore:.4f}"
    print(f"views to 95 % of the ceiling {doc['views_to_95']}, AUC {doc['auc']:.3f}{surface}; wrote {out}/metrics.json")
    return doc
