"""re-run a journaled session headless and check that it reproduces its metrics

``nbv replay DATA_DIR/sessions/ID`` feeds the journaled frames, in their order,
through a fresh Planner with the journaled config and seed (workbench/journal/check.py),
re-makes every journaled plan, and compares points, voxel counts, coverage and
each plan's best view and score with the journal. It prints a table, writes
``metrics.json`` (the layout of ``nbv scan``'s, plus the comparison) and
``cloud.ply`` to ``--out``, and exits 0 when everything matched, 1 when not.
Used by ``nbv.cli`` as ``add_arguments(parser)`` / ``run(args) -> int``.
"""

from __future__ import annotations

import argparse
import json
from pathlib import Path
from typing import Any


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("journal", type=Path, metavar="DIR", help="a session folder (DATA_DIR/sessions/ID)")
    parser.add_argument(
        "--out", type=Path, default=Path("out/replay"), help="output directory (metrics.json, cloud.ply)"
    )
    parser.add_argument(
        "--models-dir",
        type=Path,
        default=None,
        help="where the session's model file is, for coverage (default: the server's)",
    )


def _iteration(capture: Any) -> dict[str, Any]:
    """One row of metrics.json: nbv scan's record of the capture and the (last) plan made from it, replayed,
    and what the journal recorded."""
    from workbench import best_of
    from workbench.evaluation import make_record

    ev = capture.event
    plan_event, plan = capture.plans[-1] if capture.plans else (None, None)
    best = None if plan is None else best_of(plan)
    recorded = None if plan_event is None else plan_event.get("best")
    return {
        **make_record(capture.report, plan, capture.voxels, capture.coverage).to_json(),
        "best_score": None if best is None else best["score"],
        "journal": {
            "points": ev.get("points"),
            "coverage": ev.get("coverage"),
            "voxels": ev.get("voxels"),
            "next_view": None if recorded is None else recorded["index"],
            "best_score": None if recorded is None else recorded["score"],
            "plan_id": None if plan_event is None else plan_event["plan_id"],
        },
    }


def _table(rows: list[dict[str, Any]], mismatches: list[str]) -> None:
    from rich.console import Console
    from rich.table import Table

    table = Table(title="replay vs journal (a / b: replay / journal where they differ)")
    for name in ("view", "points", "coverage", "occ", "front", "next", "score", "match"):
        table.add_column(name, justify="right")
    for r in rows:
        j = r["journal"]
        same = (
            r["points"] == j["points"]
            and r["next_view"] == j["next_view"]
            and not any(m.startswith((f"capture {r['index']}:", f"plan {j['plan_id']}")) for m in mismatches)
        )
        cov = "-" if r["coverage"] is None else f"{r['coverage']:.4f}"
        score = "-" if r["best_score"] is None else f"{r['best_score']:.1f}"
        table.add_row(
            str(r["index"]),
            _pair(r["points"], j["points"]),
            cov,
            str(r["n_occupied"]),
            str(r["n_frontier"]),
            _pair(r["next_view"], j["next_view"]),
            score,
            "ok" if same else "DIFFERS",
        )
    Console(highlight=False, width=110).print(table)


def _pair(replayed: Any, recorded: Any) -> str:
    return str(replayed) if replayed == recorded else f"{replayed} / {recorded}"


def run(args: argparse.Namespace) -> int:
    """Replay, report, write the outputs; 0 when the journal was reproduced, 1 when not."""
    from devices.ply import write_ply
    from workbench.journal import check_journal

    replay = check_journal(args.journal, args.models_dir)
    journal, rebuilt = replay.journal, replay.rebuilt
    rows = [_iteration(c) for c in rebuilt.captures]
    _table(rows, rebuilt.mismatches)
    out: Path = args.out
    out.mkdir(parents=True, exist_ok=True)
    doc = {
        "model": journal.header["model"]["name"],
        "planner": "projection",
        "config": rebuilt.config.to_dict(),
        "reachable_coverage": None,
        "iterations": rows,
        "final_coverage": rows[-1]["coverage"] if rows else None,
        "terminated": rebuilt.planner.terminated,
        "seconds": replay.seconds,
        "session": journal.session_id,
        "journal": str(args.journal),
        "plans": sum(len(c.plans) for c in rebuilt.captures),
        "reproduced": not rebuilt.mismatches,
        "mismatches": rebuilt.mismatches,
    }
    (out / "metrics.json").write_text(json.dumps(doc, indent=2))
    write_ply(out / "cloud.ply", rebuilt.planner.cloud)
    verdict = "reproduced" if not rebuilt.mismatches else f"DIFFERS ({len(rebuilt.mismatches)} difference(s))"
    print(f"{len(rows)} views, {doc['plans']} plans: {verdict}; wrote {out}/metrics.json, {out}/cloud.ply")
    for line in rebuilt.mismatches:
        print(f"  {line}")
    return 0 if not rebuilt.mismatches else 1
