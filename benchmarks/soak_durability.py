"""The model-based durability test (tests/workbench/test_durability_model.py) with many more examples.

Random runs of create / capture / plan / approve / step / discard / delete / stop / graceful and abrupt
restarts / resume / a full disk / sleep / wake / a viewer across sleep and wake / creates released together at
the live-session limit / a read in flight while sleeps are asked, through the registry, checking after every rule
that every acknowledged view is journaled and survives restarts, sleeps and wakes, that nothing unacknowledged
appears, that never more than the limit are live, that a viewer hears every view and that no valid request is
answered 422 or 5xx. Prints the example count, the steps per example and the time.

    .venv/bin/python benchmarks/soak_durability.py [--examples 200] [--steps 30] [--seed N] [--minutes M]

``--minutes M``: run batches of ``--examples`` (each from its own seed) until M minutes have passed.
"""

from __future__ import annotations

import argparse
import logging
import sys
import time
from pathlib import Path

from hypothesis import HealthCheck, settings
from hypothesis.stateful import run_state_machine_as_test

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
from tests.workbench.test_durability_model import Durability


def main() -> None:
    parser = argparse.ArgumentParser(description="the model-based durability test with many more examples")
    parser.add_argument("--examples", type=int, default=200)
    parser.add_argument("--steps", type=int, default=30)
    parser.add_argument("--seed", type=int, default=None, help="a fixed seed (default: random)")
    parser.add_argument("--minutes", type=float, default=0.0, help="run batches until this long (0: one batch)")
    args = parser.parse_args()
    logging.disable(logging.ERROR)  # the full-disk rule makes the sessions log every refused write
    t0 = time.monotonic()
    batches = 0
    while True:
        options = settings(
            max_examples=args.examples,
            stateful_step_count=args.steps,
            deadline=None,
            suppress_health_check=[HealthCheck.too_slow, HealthCheck.filter_too_much, HealthCheck.data_too_large],
            derandomize=args.seed is not None and batches == 0,  # later batches: fresh random runs
            database=None,
        )
        run_state_machine_as_test(Durability, settings=options)
        batches += 1
        elapsed = time.monotonic() - t0
        print(
            f"batch {batches}: {args.examples} examples x up to {args.steps} steps passed ({elapsed:.1f} s)", flush=True
        )
        if elapsed >= args.minutes * 60:
            break
    print(
        f"durability soak: {batches} batch(es), {batches * args.examples} examples x up to {args.steps} steps "
        f"passed in {elapsed:.1f} s"
    )


if __name__ == "__main__":
    main()
