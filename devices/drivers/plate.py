"""Plate angle <-> motor axis units, shared by the turntable drivers (GRBL, Modbus RTU).

A turntable's controller counts in its own units (GRBL axis units, drive steps). ``units_per_degree``
scales them, ``invert`` flips the direction (positive units turning the plate clockwise seen from
above), ``zero_offset_deg`` is the plate angle at unit 0. A *continuous* plate may turn without limit,
so each move takes the short way from where it is; otherwise targets stay in [-180, 180] degrees (a
plate with cables).
"""

from __future__ import annotations

import math
from dataclasses import dataclass


def wrap_deg(a: float) -> float:
    """``a`` degrees wrapped to (-180, 180]."""
    w = math.remainder(a, 360.0)
    return 180.0 if w == -180.0 else w


@dataclass(frozen=True)
class PlateScale:
    """How controller units map to plate degrees (see the module docstring)."""

    units_per_degree: float
    invert: bool = False
    zero_offset_deg: float = 0.0
    continuous: bool = True

    def plate_deg(self, units: float) -> float:
        """The plate angle (degrees, not wrapped) at controller position ``units``."""
        sign = -1.0 if self.invert else 1.0
        return sign * units / self.units_per_degree + self.zero_offset_deg

    def units(self, plate_deg: float) -> float:
        """The controller position that puts the plate at ``plate_deg``."""
        sign = -1.0 if self.invert else 1.0
        return sign * (plate_deg - self.zero_offset_deg) * self.units_per_degree

    def target_deg(self, current_deg: float, wanted_rad: float) -> float:
        """The plate target in degrees for a requested angle: the short way from ``current_deg`` when
        continuous, else the wanted angle wrapped to (-180, 180]."""
        wanted = math.degrees(wanted_rad)
        return current_deg + wrap_deg(wanted - current_deg) if self.continuous else wrap_deg(wanted)


def check_angle(angle: object) -> float:
    """``angle`` as a float, or ValueError naming the field (a finite number of radians, not a bool)."""
    if not isinstance(angle, int | float) or isinstance(angle, bool) or not math.isfinite(angle):
        raise ValueError(f"angle: must be a finite number (radians), got {angle!r}")
    return float(angle)
