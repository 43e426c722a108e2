"""Where a running plan is: stage k of n by name, and items done in it (for a caller that shows progress).

The planner stays a plain library: ``Planner.plan(progress=...)`` calls a function with a
:class:`PlanProgress` at each stage's start and as items (candidates, values of T, batches of views) are done.
What the caller does with it (throttle, ship over a pipe, push to a page) is its business.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import dataclass


@dataclass(frozen=True)
class PlanProgress:
    """Stage ``step`` of ``steps`` (1-based), named ``stage``; ``done`` of ``total`` items of it are done."""

    stage: str
    step: int
    steps: int
    done: int
    total: int

    @property
    def fraction(self) -> float:
        """0..1 of the whole plan, each stage counting the same (its items share it evenly)."""
        inside = self.done / self.total if self.total > 0 else 0.0
        return min(1.0, max(0.0, (self.step - 1 + min(inside, 1.0)) / max(self.steps, 1)))

    def to_dict(self) -> dict[str, object]:
        return {"stage": self.stage, "step": self.step, "steps": self.steps, "done": self.done, "total": self.total}


ProgressFn = Callable[[PlanProgress], None]
"""Called with each new position of a plan."""

StageFn = Callable[[str, int, int], None]
"""``(stage, done, total)``: how a stage reports (an evaluator gets one in its context)."""


def ignore(stage: str, done: int, total: int) -> None:
    """A :data:`StageFn` that reports nowhere."""


class Stages:
    """Numbers the stages of one plan and forwards ``(stage, done, total)`` to a :data:`ProgressFn`.

    stages: the names in the order they run. A stage not named there is added at the end (steps grows).
    """

    def __init__(self, stages: Sequence[str], sink: ProgressFn | None) -> None:
        self.names = list(stages)
        self.sink = sink

    def __call__(self, stage: str, done: int, total: int) -> None:
        if self.sink is None:
            return
        if stage not in self.names:
            self.names.append(stage)
        self.sink(PlanProgress(stage, self.names.index(stage) + 1, len(self.names), int(done), int(total)))
