"""What the worker process costs: a plan and an approve (move, render, integrate) with and without the hop.

Two registries on the same model, config and seed: one runs the heavy steps in the session's worker process
(``workers = true``, the server's default), the other in the calling process (``workers = false``). Each
session captures its first view, then ``--views`` times plans and approves the best view; the table gives
the median and the fastest wall time of ``Session.plan`` and ``Session.approve``, and the size of the planner
shipped to the worker and back (pickle) after the last view. Plans and views are the same in both (the worker
works on a copy of the same planner), which the script checks.

    .venv/bin/python benchmarks/bench_worker_hop.py [--model l-block] [--views 4] [--resolution 0.01]
"""

from __future__ import annotations

import argparse
import pickle
import statistics
import tempfile
import time
from pathlib import Path
from typing import Any

from workbench import SessionRegistry, WorkbenchSettings


def run(workers: bool, model: str, views: int, config: dict[str, Any]) -> dict[str, Any]:
    """Times (s) of each plan and approve of one session; its plans' best indices; the planner's pickle size."""
    with tempfile.TemporaryDirectory() as data:
        registry = SessionRegistry(WorkbenchSettings(data_dir=Path(data), workers=workers))
        try:
            session = registry.create(model=model, config=config, seed=0)
            if session.worker is not None:
                session.worker.start()  # started in the background at create: not part of the first step
            session.capture()
            plans, approves, best = [], [], []
            for _ in range(views):
                t0 = time.perf_counter()
                entry = session.plan()
                plans.append(time.perf_counter() - t0)
                best.append(entry.plan.best_index)
                if entry.plan.best_index is None:
                    break
                t0 = time.perf_counter()
                session.approve(entry.plan_id, entry.plan.best_index)
                approves.append(time.perf_counter() - t0)
            size = len(pickle.dumps(session.planner))
        finally:
            registry.close()
    return {"plan": plans, "approve": approves, "best": best, "bytes": size}


def main() -> None:
    parser = argparse.ArgumentParser(description=(__doc__ or "").splitlines()[0])
    parser.add_argument("--model", default="l-block")
    parser.add_argument("--views", type=int, default=4)
    parser.add_argument("--resolution", type=float, default=0.01)
    args = parser.parse_args()
    config = {"voxel": {"resolution": args.resolution}}
    results = {hop: run(hop, args.model, args.views, config) for hop in (False, True)}
    if results[False]["best"] != results[True]["best"]:
        print(f"!! the plans differ: {results[False]['best']} vs {results[True]['best']}")
    print(
        f"model {args.model}, {args.views} views, voxel {args.resolution} m; planner pickle "
        f"{results[True]['bytes'] / 1e6:.1f} MB after the last view"
    )
    print(f"{'step':<8} {'in process':>22} {'worker process':>22} {'hop (median)':>14}")
    for step in ("plan", "approve"):
        a, b = results[False][step], results[True][step]
        cell = lambda xs: f"{statistics.median(xs):7.3f} (min {min(xs):.3f}) s"  # noqa: E731
        print(f"{step:<8} {cell(a):>22} {cell(b):>22} {statistics.median(b) - statistics.median(a):+13.3f}s")


if __name__ == "__main__":
    main()
