"""The candidate hemisphere (paper §III-B)."""

from __future__ import annotations

import math
from collections import Counter

import numpy as np
import pytest

from planner.candidates import parallel_elevations, propose_candidates, share_out
from planner.config import CandidateConfig, PartitionConfig
from planner.partitions import azimuth_of, sector_of
from planner.types import BoundingBox

BOX = BoundingBox(np.array([-0.1, -0.05, 0.0]), np.array([0.1, 0.15, 0.2]))  # centre (0, 0.05, 0.1)


def test_radius_is_working_distance_plus_half_diagonal_and_all_look_at_the_centre() -> None:
    cands, center, radius = propose_candidates(BOX, CandidateConfig(), PartitionConfig())
    np.testing.assert_allclose(center, [0.0, 0.05, 0.1])
    assert radius == pytest.approx(0.35 + 0.5 * math.sqrt(3 * 0.2**2))
    pos = np.stack([c.position for c in cands])
    np.testing.assert_allclose(np.linalg.norm(pos - center, axis=1), radius)
    axes = np.stack([c.T_world_camera.rotation[:, 2] for c in cands])
    np.testing.assert_allclose(np.einsum("ni,ni->n", axes, (center - pos) / radius), 1.0)
    # upright: image +y (down) has a negative world z component
    assert np.all(np.stack([c.T_world_camera.rotation[2, 1] for c in cands]) < 0)
    assert [c.index for c in cands] == list(range(400))


def test_exactly_n_views_shared_in_proportion_to_parallel_length() -> None:
    cfg = CandidateConfig(count=400, parallels=10, min_elevation_deg=10.0, max_elevation_deg=85.0)
    cands, center, radius = propose_candidates(BOX, cfg, PartitionConfig())
    assert len(cands) == 400
    elev = np.radians(np.linspace(10.0, 85.0, 10))
    np.testing.assert_allclose(parallel_elevations(cfg), elev)
    counts = Counter(c.parallel for c in cands)
    quota = 400 * np.cos(elev) / np.cos(elev).sum()
    got = np.array([counts[p] for p in range(10)])
    assert np.all(np.abs(got - quota) < 1.0) and got.sum() == 400
    assert got[0] == 64 and got[-1] == 6  # 63.7 and 5.96 (ends inclusive: 10 and 85 degrees)
    for c in cands:
        assert c.elevation == pytest.approx(elev[c.parallel])
        assert c.position[2] - center[2] == pytest.approx(radius * math.sin(elev[c.parallel]))
    assert min(c.position[2] for c in cands) - center[2] == pytest.approx(radius * math.sin(math.radians(10)))


def test_azimuths_are_equally_spaced_and_staggered() -> None:
    cands, center, _ = propose_candidates(BOX, CandidateConfig(count=30, parallels=3), PartitionConfig())
    for p in range(3):
        az = np.array([c.azimuth for c in cands if c.parallel == p])
        n = len(az)
        step = 2 * math.pi / n
        start = 0.5 * step if p % 2 else 0.0
        np.testing.assert_allclose(az, start + step * np.arange(n))
        assert np.all((az >= 0) & (az < 2 * math.pi))
    for c in cands:
        assert azimuth_of(c.position, center) == pytest.approx(c.azimuth, abs=1e-9)


def test_sectors_come_from_the_partition_config() -> None:
    parts = PartitionConfig(sectors=4, offset_deg=45.0)
    cands, center, _ = propose_candidates(BOX, CandidateConfig(), parts)
    for c in cands:
        assert c.sector == sector_of(azimuth_of(c.position, center), parts)
    first = [c for c in cands if c.parallel == 0]  # azimuths 0, 2pi/64, ...
    assert first[0].sector == 3  # azimuth 0 is in [315, 360) degrees
    assert Counter(c.sector for c in first) == {0: 16, 1: 16, 2: 16, 3: 16}


def test_single_parallel_sits_midway_and_output_is_deterministic() -> None:
    cfg = CandidateConfig(count=12, parallels=1, min_elevation_deg=20.0, max_elevation_deg=40.0)
    a, _, _ = propose_candidates(BOX, cfg, PartitionConfig())
    b, _, _ = propose_candidates(BOX, cfg, PartitionConfig())
    assert all(c.elevation == pytest.approx(math.radians(30.0)) for c in a)
    assert len(a) == 12
    for x, y in zip(a, b, strict=True):
        np.testing.assert_array_equal(x.T_world_camera.matrix, y.T_world_camera.matrix)


def test_share_out_largest_remainder() -> None:
    assert share_out(10, np.array([1.0, 1.0, 1.0])).tolist() == [4, 3, 3]  # tie -> lowest index
    assert share_out(7, np.array([0.5, 0.3, 0.2])).tolist() == [4, 2, 1]  # 3.5, 2.1, 1.4
    assert share_out(5, np.array([1.0, 0.0, 9.0])).tolist() == [1, 0, 4]  # 0.5, 0, 4.5: tie -> lowest index
    assert share_out(0, np.array([1.0, 2.0])).tolist() == [0, 0]
    with pytest.raises(ValueError, match="weights"):
        share_out(3, np.array([0.0, 0.0]))


def test_degenerate_box_and_bad_input() -> None:
    point = BoundingBox(np.array([0.0, 0.0, 0.1]), np.array([0.0, 0.0, 0.1]))
    _, _, radius = propose_candidates(point, CandidateConfig(working_distance=0.4), PartitionConfig())
    assert radius == pytest.approx(0.4)
    with pytest.raises(ValueError, match="bbox"):
        propose_candidates(None, CandidateConfig(), PartitionConfig())  # type: ignore[arg-type]
    with pytest.raises(ValueError, match="partitions"):
        propose_candidates(BOX, CandidateConfig(), CandidateConfig())  # type: ignore[arg-type]
    with pytest.raises(ValueError, match="config"):
        propose_candidates(BOX, PartitionConfig(), PartitionConfig())  # type: ignore[arg-type]


def test_a_range_limited_sensor_pulls_the_sphere_in() -> None:
    """``max_range`` 0 is the paper's R = d_c + d_b; a 0.5 m sensor keeps B's far corner within range, and the
    camera never comes nearer than MIN_STANDOFF outside B's sphere."""
    from planner.candidates import MIN_STANDOFF, sphere_radius

    assert sphere_radius(CandidateConfig(), 0.15) == pytest.approx(0.35 + 0.15)
    assert sphere_radius(CandidateConfig(max_range=3.0), 0.15) == pytest.approx(0.5)  # in range: unchanged
    assert sphere_radius(CandidateConfig(max_range=0.5), 0.15) == pytest.approx(0.35)
    assert sphere_radius(CandidateConfig(max_range=0.5), 0.3) == pytest.approx(0.3 + MIN_STANDOFF)
    box = BoundingBox(np.array([-0.1, -0.1, 0.0]), np.array([0.1, 0.1, 0.2]))
    _, _, radius = propose_candidates(box, CandidateConfig(max_range=0.5), PartitionConfig())
    assert radius + 0.5 * box.diagonal == pytest.approx(0.5)
    with pytest.raises(ValueError, match=r"candidates\.max_range"):
        CandidateConfig(max_range=-1.0)


def test_held_aim_keeps_the_box_while_every_face_stays_within_the_tolerance() -> None:
    """``held_aim``: the previous box while no face moved more than the tolerance, else the new one; measured against
    the held box, so many small steps cannot drift it further than the tolerance; no previous box or tolerance 0:
    the new box."""
    from planner.candidates import held_aim

    a = BoundingBox(np.array([0.0, 0.0, 0.0]), np.array([0.2, 0.2, 0.2]))
    near = BoundingBox(np.array([-0.01, 0.0, 0.0]), np.array([0.2, 0.21, 0.2]))  # two faces one voxel out
    far = BoundingBox(np.array([-0.02, 0.0, 0.0]), np.array([0.2, 0.2, 0.2]))  # one face two voxels out
    assert held_aim(None, a, 0.015) is a
    assert held_aim(a, near, 0.015) is a
    assert held_aim(a, near, 0.0) is near
    assert held_aim(a, far, 0.015) is far
    assert held_aim(a, far, 0.025) is a
    # one voxel a step: held for the first step, the third box (two voxels from the held one) is taken
    steps = [BoundingBox(np.array([-0.01 * k, 0.0, 0.0]), np.array([0.2, 0.2, 0.2])) for k in (1, 2)]
    held = a
    taken = []
    for box in steps:
        held = held_aim(held, box, 0.015)
        taken.append(held)
    assert taken[0] is a and taken[1] is steps[1]


def test_the_same_box_gives_the_same_candidates_without_building_them_again() -> None:
    """A held or unchanged box: the kept set (the same objects), equal to a fresh build; another box, config or
    partition layout: its own set; the kept sets are bounded."""
    import planner.candidates as module

    box = BoundingBox(np.array([-0.1, -0.1, 0.0]), np.array([0.1, 0.12, 0.2]))
    first = propose_candidates(box, CandidateConfig(), PartitionConfig())
    again = propose_candidates(BoundingBox(box.lower.copy(), box.upper.copy()), CandidateConfig(), PartitionConfig())
    assert again is first
    fresh = module._proposed(box, CandidateConfig(), PartitionConfig())
    assert fresh[0] is not first[0] and fresh[2] == first[2] and np.array_equal(fresh[1], first[1])
    for a, b in zip(fresh[0], first[0], strict=True):
        assert np.array_equal(a.T_world_camera.matrix, b.T_world_camera.matrix)
        assert (a.index, a.elevation, a.azimuth, a.parallel, a.sector) == (
            b.index,
            b.elevation,
            b.azimuth,
            b.parallel,
            b.sector,
        )
    moved = BoundingBox(box.lower, box.upper + np.array([0.0, 0.0, 0.01]))
    assert propose_candidates(moved, CandidateConfig(), PartitionConfig()) is not first
    assert propose_candidates(box, CandidateConfig(count=200), PartitionConfig()) is not first
    assert propose_candidates(box, CandidateConfig(), PartitionConfig(sectors=6)) is not first
    for k in range(3 * module._RECENT_SIZE):
        propose_candidates(BoundingBox(box.lower, box.upper + 0.001 * k), CandidateConfig(), PartitionConfig())
    assert len(module._RECENT) <= module._RECENT_SIZE
