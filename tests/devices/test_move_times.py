"""The tour's move times (``Cell.move_times``) come from the cached reachability targets at every plate angle: each
view is entered at the plate angle with the shortest move from the current state, and the move between two views
goes to the nearest of the second one's targets."""

from __future__ import annotations

import math
from types import SimpleNamespace

import numpy as np
import pytest

from devices.builtins import make_builtin
from devices.cell import Cell
from devices.sim import make_sim_cell
from planner.types import BoundingBox, Pose
from tests.helpers import orbit_view

TARGET = np.array([0.0, 0.0, 0.08])


def view(elevation_deg: float, azimuth_deg: float, distance: float = 0.45) -> Pose:
    return orbit_view(TARGET, elevation_deg, azimuth_deg, distance)


@pytest.fixture(scope="module")
def cell() -> Cell:
    c = make_sim_cell(make_builtin("l-block", 0.2))
    c.set_object_box(BoundingBox(np.array([-0.1, -0.1, 0.0]), np.array([0.1, 0.1, 0.2])))
    return c


def test_move_times_enter_each_view_at_its_nearest_plate_angle(cell: Cell) -> None:
    reach = cell.kinematics.reach  # type: ignore[union-attr]
    q0, a0 = cell.arm.joint_positions(), cell.angle
    poses = [view(el, az) for el in (25.0, 50.0) for az in range(0, 360, 60)]
    candidates = [SimpleNamespace(T_world_camera=T) for T in poses]
    times = cell.move_times(candidates, range(len(poses)))
    entries = []
    several = shorter = 0
    for k, T in enumerate(poses, start=1):
        options = reach.free_targets(T, q0, a0)
        if not options:
            assert times[0, k] == math.inf
            entries.append(None)
            continue
        seconds = [reach.move_seconds(q0, q, a0, a) for q, a in options]
        assert times[0, k] == pytest.approx(min(seconds), abs=1e-9)
        entries.append(options[int(np.argmin(seconds))])
        several += len({round(a, 9) for _, a in options}) > 1
        # the reachability target alone (the first plate angle that serves) is what the times came from before
        first, _ = reach.reachability(T, q0, a0)
        assert first is not None
        shorter += min(seconds) < reach.move_seconds(q0, first.q, a0, first.angle) - 0.1
    assert several >= 6 and shorter >= 2  # several plate angles serve, and another one is often nearer
    for i, entry in enumerate(entries, start=1):  # the move between two views: from i's entry to j's nearest target
        for j, T in enumerate(poses, start=1):
            if entry is None or entries[j - 1] is None or i == j:
                continue
            want = min(reach.move_seconds(entry[0], q, entry[1], a) for q, a in reach.free_targets(T, q0, a0))
            assert times[i, j] == pytest.approx(want, abs=1e-9)
    assert np.all(np.diag(times) == 0.0)
