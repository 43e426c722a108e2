"""benchmarks/bench_tour_oracle.py's search: the quickest sequence of views to a goal on a hand-made problem."""

from __future__ import annotations

import importlib.util
import math
import sys
from pathlib import Path
from types import ModuleType

import numpy as np
import pytest

ROOT = Path(__file__).resolve().parents[2]


@pytest.fixture(scope="module")
def oracle() -> ModuleType:
    spec = importlib.util.spec_from_file_location("bench_tour_oracle", ROOT / "benchmarks" / "bench_tour_oracle.py")
    assert spec is not None and spec.loader is not None
    module = importlib.util.module_from_spec(spec)
    sys.modules[spec.name] = module  # dataclasses look their module up
    spec.loader.exec_module(module)
    return module


def problem() -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Four views of 12 elements: A sees 0-5 (far), B 6-9 (near), C 0-3 (near B through its second target), D = B.

    Targets (nodes): 0 A, 1 B, 2 C at a far plate angle, 3 C near B, 4 D."""
    masks = np.zeros((4, 12), dtype=bool)
    masks[0, 0:6] = True
    masks[1, 6:10] = True
    masks[2, 0:4] = True
    masks[3, 6:10] = True
    owner = np.array([0, 1, 2, 2, 3])
    start = np.array([5.0, 1.0, 6.0, 2.5, 1.0])
    times = np.full((5, 5), 9.0)
    np.fill_diagonal(times, 0.0)
    times[1, 3] = times[3, 1] = 1.0  # B <-> C's near target
    times[1, 2] = 4.0
    times[1, 4] = times[4, 1] = 0.2  # B <-> D: the same surface, a short move
    times[0, 1] = times[0, 3] = 9.0
    return masks, owner, times, start


def test_the_search_finds_the_quickest_sequence_not_the_greedy_one(oracle: ModuleType) -> None:
    masks, owner, times, start = problem()
    found = oracle.beam_search(masks, owner, times, start, np.zeros(12, bool), 8, 8, 1.0, 4, 0.5)
    # greedy by gain takes A first (6 new) and needs B next: 5 + 9 + 2 x 0.5 = 15 s; B then C's near target: 1 + 1 + 1
    assert found.views == [1, 2]
    assert math.isclose(found.predicted_seconds, 3.0)
    assert found.predicted_coverage == 8


def test_a_surface_two_views_see_counts_once(oracle: ModuleType) -> None:
    masks, owner, times, start = problem()
    # B and D see the same 4 elements: B then D (1.2 s) covers 4, not 8; the quickest past 5 adds C
    found = oracle.beam_search(masks, owner, times, start, np.zeros(12, bool), 5, 8, 1.0, 4, 0.0)
    assert found.views == [1, 2]
    assert math.isclose(found.predicted_seconds, 2.0)
    assert oracle.beam_search(masks[[1, 3]], np.array([0, 1]), times[np.ix_([1, 4], [1, 4])], start[[1, 4]],
                              np.zeros(12, bool), 5, 8, 1.0, 4, 0.0) is None  # fmt: skip


def test_elements_covered_before_count_and_the_view_limit_holds(oracle: ModuleType) -> None:
    masks, owner, times, start = problem()
    covered = np.zeros(12, dtype=bool)
    covered[0:4] = True  # what C would add is there already: A is the only way past 8
    found = oracle.beam_search(masks, owner, times, start, covered, 10, 8, 1.0, 4, 0.0)
    assert found.views == [1, 0]  # B then A: 1 + 9 s; A then B: 5 + 9 s
    assert math.isclose(found.predicted_seconds, 10.0)
    assert oracle.beam_search(masks, owner, times, start, covered, 10, 8, 1.0, 1, 0.0) is None  # one view: short
