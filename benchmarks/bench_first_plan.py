"""The first plan after a create, as the page makes it: a session with its worker process (the server's default),
the first view captured ``--think`` seconds after the create (the person looking at the page), then the plan.

The worker process starts at the create and, before its first job, builds the planning cell's arm model and warms
its IK on a nominal hemisphere (``workbench/workers/child.py``, the ``warm`` job), so the plan pays neither
(goal: <= 1 s for the bunny with the UR5). Prints the wall time of the capture and of each of ``--plans`` plans
(each after approving the previous plan's best view), per run.

    .venv/bin/python benchmarks/bench_first_plan.py [--model bunny.obj] [--think 3] [--runs 3]
        [--sensor realsense-d435 --calibration typical]

To measure another checkout's code the same way, run it from that checkout's directory (``cd /path/to/checkout;
PYTHONPATH=. /path/to/.venv/bin/python benchmarks/bench_first_plan.py``): the workers come from a forkserver, and on
Python 3.11 a forkserver puts its working directory first on ``sys.path`` (it ignores the parent's path), so a
PYTHONPATH alone would measure the code of the directory it was started from.
"""

from __future__ import annotations

import argparse
import statistics
import tempfile
import time
from pathlib import Path
from typing import Any

from workbench import SessionRegistry, WorkbenchSettings


def one_run(model: str, think: float, plans: int, camera: dict[str, Any], planner: str) -> dict[str, Any]:
    """Seconds of the first capture and of each plan of one new session."""
    with tempfile.TemporaryDirectory() as data:
        registry = SessionRegistry(WorkbenchSettings(data_dir=Path(data), workers=True))
        try:
            t0 = time.perf_counter()
            session = registry.create(model=model, seed=0, camera=camera, planner=planner)
            created = time.perf_counter() - t0
            time.sleep(think)
            t0 = time.perf_counter()
            session.capture()
            capture = time.perf_counter() - t0
            seconds = []
            for _ in range(plans):
                t0 = time.perf_counter()
                entry = session.plan()
                seconds.append(time.perf_counter() - t0)
                if entry.plan.best_index is None or len(seconds) == plans:
                    break
                session.approve(entry.plan_id, entry.plan.best_index)
        finally:
            registry.close()
    return {"create": created, "capture": capture, "plans": seconds}


def main() -> None:
    parser = argparse.ArgumentParser(description=(__doc__ or "").splitlines()[0])
    parser.add_argument("--model", default="bunny.obj", help="a model the server knows (default bunny.obj)")
    parser.add_argument("--think", type=float, default=3.0, help="seconds between the create and the capture")
    parser.add_argument("--runs", type=int, default=3)
    parser.add_argument("--plans", type=int, default=3)
    parser.add_argument("--planner", default="projection")
    parser.add_argument("--sensor", default="ideal")
    parser.add_argument("--calibration", default="none")
    args = parser.parse_args()
    camera = {"sensor": args.sensor, "calibration": args.calibration}
    runs = [one_run(args.model, args.think, args.plans, camera, args.planner) for _ in range(args.runs)]
    print(f"{args.model}, {args.planner}, sensor {args.sensor}, calibration {args.calibration}, think {args.think} s")
    for i, r in enumerate(runs):
        plans = ", ".join(f"{s:.3f}" for s in r["plans"])
        print(f"run {i}: create {r['create']:.3f} s, capture {r['capture']:.3f} s, plans {plans} s")
    first = [r["plans"][0] for r in runs]
    print(f"first plan after a create: median {statistics.median(first):.3f} s, max {max(first):.3f} s")


if __name__ == "__main__":
    main()
