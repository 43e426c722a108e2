"""Helpers every test package shares: the small planner config, free ports, waiting for a session's state."""

from __future__ import annotations

import dataclasses
import math
import socket
import threading
from collections.abc import Callable, Iterable
from typing import Any

import numpy as np
from numpy.typing import ArrayLike

from devices.config import CameraConfig
from planner import PlannerConfig, Pose

SMALL: dict[str, Any] = {
    "voxel": {"resolution": 0.02},
    "candidates": {"count": 60, "parallels": 4},
    "cluster": {"t_min": 2, "t_max": 6},
}
"""A coarse map and few candidates: a capture + plan takes well under a second."""

SMALL_CONFIG = PlannerConfig().replace(**SMALL)
"""``SMALL`` as a PlannerConfig."""

SMALL_CAMERA = CameraConfig(width=320, height=240, fx=305.0, fy=305.0, cx=159.5, cy=119.5)
"""The simulated camera of the API and browser tests' servers: the default's field of view at half its resolution
(a quarter of the rays, points and frame bytes of a view). What those tests check does not depend on the pixel
count; the tests of the camera, the surface and the sensors run at the default's."""


SMALL_SCORE_POINTS = 20_000
"""The ``surface_score_points`` of the API and browser tests' servers: a fifth of the default's points on each
view's surface when it is scored (0.03-0.05 s of CPU a view instead of 0.11-0.18, docs/experiments/surface.md). Those tests
check that the scores are there, in range and the same after a resume or a discard, not their value; the tests
of the surface and its scoring (tests/workbench/test_surface*.py) run at the default."""


def with_small_costs(settings: Any) -> Any:
    """``settings`` (an ``AppSettings`` or ``WorkbenchSettings``) with :data:`SMALL_CAMERA` as its simulated camera
    and :data:`SMALL_SCORE_POINTS` on each scored surface."""
    camera = dataclasses.replace(settings.devices, camera=SMALL_CAMERA)
    return dataclasses.replace(settings, devices=camera, surface_score_points=SMALL_SCORE_POINTS)


def small_costs_toml() -> str:
    """:func:`with_small_costs` as an ``nbv serve --config`` file (a server process's): :data:`SMALL_SCORE_POINTS`
    in its ``[server]`` table, :data:`SMALL_CAMERA` in ``[devices]`` (the fields where it differs from the default
    camera)."""
    default = CameraConfig()
    fields = [f.name for f in dataclasses.fields(CameraConfig)]
    changed = [f"{k} = {getattr(SMALL_CAMERA, k)!r}" for k in fields if getattr(SMALL_CAMERA, k) != getattr(default, k)]
    server = f"[server]\nsurface_score_points = {SMALL_SCORE_POINTS}\n"
    return f"{server}[devices]\ncamera = {{ {', '.join(changed)} }}\n"


SMALL_FLAGS = ["--resolution", "0.02", "--candidates", "60", "--t-min", "2", "--t-max", "6"]
"""``SMALL`` as ``nbv scan`` / ``nbv bench`` flags (the default 10 parallels)."""


def free_port() -> int:
    """A TCP port on 127.0.0.1 that nothing listens on now."""
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def wait_for_state(session: Any, states: Iterable[str], timeout: float = 60.0) -> str:
    """Block until ``session`` (a workbench Session) is in one of ``states``; woken by its events, no polling.

    Returns the state reached; AssertionError after ``timeout`` seconds.
    """
    wanted = {str(s) for s in states}
    changed = threading.Event()

    def listener(_session: Any, _event: Any) -> None:
        changed.set()

    session.listeners.append(listener)
    try:
        while str(session.state) not in wanted:
            if not changed.wait(timeout):
                raise AssertionError(f"session {session.id}: still {session.state} after {timeout} s, wanted {wanted}")
            changed.clear()
        return str(session.state)
    finally:
        session.listeners.remove(listener)


def wait_until(predicate: Callable[[], Any], timeout: float = 30.0, what: str = "condition") -> Any:
    """For things that send no event (a process, a socket): poll ``predicate`` every 50 ms until truthy."""
    done = threading.Event()
    deadline = timeout
    while deadline > 0:
        value = predicate()
        if value:
            return value
        done.wait(0.05)
        deadline -= 0.05
    raise AssertionError(f"{what}: not reached after {timeout} s")


def orbit_view(target: ArrayLike, elevation_deg: float, azimuth_deg: float, distance: float = 0.45) -> Pose:
    """A camera ``distance`` m from ``target`` (3,) at ``elevation_deg`` above the table plane and
    ``azimuth_deg`` about its z axis (table frame), looking at ``target``."""
    e, a = math.radians(elevation_deg), math.radians(azimuth_deg)
    at = np.asarray(target, dtype=float)
    return Pose.look_at(
        at + distance * np.array([math.cos(e) * math.cos(a), math.cos(e) * math.sin(a), math.sin(e)]), at
    )
