"""Global longitude partitions, taken views and the final choice (paper §III-F)."""

from __future__ import annotations

import math

import numpy as np
import pytest

from planner.candidates import propose_candidates
from planner.config import CandidateConfig, PartitionConfig
from planner.partitions import (
    azimuth_of,
    default_tolerance,
    eligible_sectors,
    not_taken,
    sector_edges,
    sector_of,
    select_best,
)
from planner.types import BoundingBox, Candidate, Pose, ViewScore

PI = math.pi


@pytest.mark.parametrize(
    ("azimuth", "offset", "want"),
    [
        (0.0, 0.0, 0),
        (PI / 2 - 1e-6, 0.0, 0),
        (PI / 2, 0.0, 1),
        (PI, 0.0, 2),
        (3 * PI / 2 + 0.1, 0.0, 3),
        (-0.1, 0.0, 3),
        (2 * PI, 0.0, 0),
        (7 * PI / 2 + 0.1, 0.0, 3),
        (0.0, 45.0, 3),
        (math.radians(50), 45.0, 0),
        (math.radians(44), -45.0, 0),
        (math.radians(46), -45.0, 1),
    ],
)
def test_sector_of(azimuth: float, offset: float, want: int) -> None:
    assert sector_of(azimuth, PartitionConfig(sectors=4, offset_deg=offset)) == want


def test_sector_of_other_counts() -> None:
    assert sector_of(math.radians(359), PartitionConfig(sectors=1)) == 0
    six = PartitionConfig(sectors=6)
    assert [sector_of(math.radians(a), six) for a in (0, 59, 61, 181, 300, 359)] == [0, 0, 1, 3, 5, 5]


def test_sector_edges() -> None:
    np.testing.assert_allclose(sector_edges(PartitionConfig()), [0, PI / 2, PI, 3 * PI / 2])
    np.testing.assert_allclose(sector_edges(PartitionConfig(offset_deg=-90)), [3 * PI / 2, 0, PI / 2, PI], atol=1e-12)
    edges = sector_edges(PartitionConfig(sectors=3, offset_deg=10))
    assert edges.shape == (3,) and edges.dtype == np.float64
    assert [sector_of(e, PartitionConfig(sectors=3, offset_deg=10)) for e in edges] == [0, 1, 2]


def test_eligible_sectors() -> None:
    assert eligible_sectors(set(), 4) == {0, 1, 2, 3}
    assert eligible_sectors({0}, 4) == {1, 3}
    assert eligible_sectors({0, 1}, 4) == {2, 3}
    assert eligible_sectors({0, 1, 2}, 4) == {3}
    assert eligible_sectors({3}, 4) == {0, 2}
    assert eligible_sectors({0, 1, 2, 3}, 4) == {0, 1, 2, 3}
    assert eligible_sectors({0, 3}, 6) == {1, 2, 4, 5}
    assert eligible_sectors({1, 2}, 6) == {0, 3}
    assert eligible_sectors({0}, 2) == {1}
    assert eligible_sectors({0}, 1) == {0}
    with pytest.raises(ValueError, match="scanned"):
        eligible_sectors({4}, 4)
    with pytest.raises(ValueError, match="n"):
        eligible_sectors(set(), 0)


def test_azimuth_of() -> None:
    assert azimuth_of([1.0, 1.0, 0.0], [0.0, 0.0, 0.0]) == pytest.approx(PI / 4)
    assert azimuth_of([0.0, -1.0, 5.0], [0.0, 0.0, 0.0]) == pytest.approx(3 * PI / 2)
    assert azimuth_of([0.5, 0.2, 0.0], [1.0, 0.2, 0.3]) == pytest.approx(PI)
    assert azimuth_of([2.0, 0.0, 0.0], [1.0, 0.0, 0.0]) == 0.0
    with pytest.raises(ValueError, match="center"):
        azimuth_of([1.0, 0.0, 0.0], [0.0, 0.0])


def ring(n: int, radius: float = 1.0) -> list[Candidate]:
    """n candidates on the equator, equally spaced, looking at the origin."""
    out = []
    for i in range(n):
        a = 2 * PI * i / n
        pose = Pose.look_at([radius * math.cos(a), radius * math.sin(a), 0.0], [0.0, 0.0, 0.0])
        out.append(Candidate(i, pose, 0.0, a, 0, 0))
    return out


def test_default_tolerance_is_half_the_mean_spacing() -> None:
    assert default_tolerance(ring(8)) == pytest.approx(PI / 8)
    assert default_tolerance(ring(8, 3.0), center=[0.0, 0.0, 0.0]) == pytest.approx(PI / 8)
    assert default_tolerance(ring(1)) == 0.0
    bbox = BoundingBox(np.array([-0.1, -0.1, 0.0]), np.array([0.1, 0.1, 0.2]))
    cands, center, _ = propose_candidates(bbox, CandidateConfig(), PartitionConfig())
    tol = default_tolerance(cands, center)
    assert 0.02 < tol < 0.1  # 400 views on ~1.7 pi sr: spacing ~0.12 rad


def test_not_taken_compares_directions_not_positions() -> None:
    cands = ring(8)
    tol = default_tolerance(cands)
    # view 3 taken from farther away (the radius grew), view 6 taken slightly off (within tolerance)
    a6 = 2 * PI * 6 / 8 + 0.5 * tol
    taken = [
        Pose.look_at([2.5 * math.cos(3 * PI / 4), 2.5 * math.sin(3 * PI / 4), 0.0], [0.0, 0.0, 0.0]),
        Pose.look_at([math.cos(a6), math.sin(a6), 0.0], [0.0, 0.0, 0.0]),
    ]
    assert not_taken(cands, taken, tol).tolist() == [True, True, True, False, True, True, False, True]
    assert not_taken(cands, taken, tol, center=[0.0, 0.0, 0.0]).tolist() == [i not in (3, 6) for i in range(8)]
    # halfway between two candidates: further than the tolerance from both
    mid = Pose.look_at([math.cos(PI / 8), math.sin(PI / 8), 0.0], [0.0, 0.0, 0.0])
    assert not_taken(cands, [mid], 0.9 * tol).all()
    assert not_taken(cands, [], tol).all()
    with pytest.raises(ValueError, match="tolerance_rad"):
        not_taken(cands, taken, -1.0)
    with pytest.raises(ValueError, match="taken\\[0\\]"):
        not_taken(cands, [np.eye(4)], tol)  # type: ignore[list-item]


def score(i: int, f: float, eligible: bool = True) -> ViewScore:
    e = np.zeros(0)
    return ViewScore(i, f, max(f, 0.0), max(-f, 0.0), eligible, np.zeros(0, dtype=np.int64), e, e, e)


def test_select_best() -> None:
    assert select_best([score(0, 1.0), score(1, 5.0), score(2, 5.0), score(3, 9.0, False)]) == 1
    assert select_best([score(0, -3.0), score(1, -2.0), score(2, -7.0)]) == 1
    assert select_best([score(0, 4.0, False), score(1, -100.0)]) == 1
    assert select_best([score(0, 4.0, False)]) is None
    assert select_best([]) is None
    with pytest.raises(ValueError, match="scores\\[0\\]"):
        select_best([score(0, float("nan"))])
