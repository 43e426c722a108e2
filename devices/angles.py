"""Angles of the cell's plate and joints: the one wrap every module of ``devices`` uses (the cell's plate angles, the
arm's IK branches and turns)."""

from __future__ import annotations

import math


def wrap_angle(angle: float) -> float:
    """``angle`` (rad) wrapped to (-pi, pi]."""
    a = math.remainder(angle, 2 * math.pi)
    return math.pi if a == -math.pi else a
