"""The named depth-sensor models of the simulated camera: what each preset's parameters are and where they come from.

A :class:`SensorModel` is a frozen set of numbers; :mod:`devices.sensors.depth_effects` applies them to a rendered
depth image and :mod:`devices.sensors.occlusion` casts the second viewpoint's rays. Sources of every figure are in
docs/experiments/sensors.md ("Sensor models"); the field docs say which figure is a vendor's and which is an assumption.

Names: ``ideal`` (today's perfect camera, the default), ``realsense-d435``, ``realsense-d405`` (Intel active stereo)
and ``structured-light`` (a projector-camera rig like the paper's).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

from planner.validate import finite, require


@dataclass(frozen=True)
class SensorModel:
    """One depth sensor's error model. Lengths in metres, angles in degrees (a config edge).

    Depth noise is the triangulation model (Intel's D400 white paper): RMS error of the depth at planar depth z
    ``sigma_z(z) = z**2 * subpixel / (focal_px * baseline)``.
    """

    name: str
    baseline: float = 0.0
    """Distance from the depth camera's optical centre to the second viewpoint (the other imager or the projector),
    along the camera's +x axis, metres (0: no second viewpoint, no triangulation noise)."""
    subpixel: float = 0.0
    """RMS of the disparity (or projector-phase) estimate, pixels."""
    focal_px: float = 0.0
    """Focal length of the device's depth stream, pixels (the noise model's; the image is rendered at the cell's
    own intrinsics)."""
    min_range: float = 0.0
    """No depth nearer than this (planar z), metres (the device's min-Z)."""
    max_range: float = math.inf
    """No depth farther than this, metres."""
    depth_unit: float = 0.0
    """Depth values are rounded to multiples of this, metres (0: no quantisation)."""
    lateral_px: float = 0.0
    """Std of a pixel's ray offset in the image plane, pixels (lateral noise: where a pixel's depth was measured)."""
    max_incidence_deg: float = 90.0
    """No depth where the surface normal is farther than this from the viewing ray, degrees (grazing incidence)."""
    flying_probability: float = 0.0
    """Chance that a pixel at a depth discontinuity returns a mixed depth between the two sides."""
    flying_jump: float = 0.01
    """A depth discontinuity: a 4-neighbour's depth differs by more than this fraction of the pixel's depth."""
    hole_fraction: float = 0.0
    """Share of the image lost to dropout blobs (specular spots, low texture), 0..1."""
    hole_size_px: int = 6
    """Edge of a dropout blob, pixels."""
    stamp_latency: float = 0.0
    """Capture during moves: how much earlier than its stamp a frame was really exposed, against the joint states
    the cell reads its pose from (the residual after the driver's clock alignment), seconds."""
    stamp_jitter: float = 0.0
    """Std of that latency from frame to frame, seconds."""
    exposure: float = 0.0
    """Exposure time of one depth frame, seconds: a move during it blurs the frame (0: instantaneous)."""

    def __post_init__(self) -> None:
        require(isinstance(self.name, str) and self.name != "", f"sensor.name: must be a name, got {self.name!r}")
        for field in (
            "baseline",
            "subpixel",
            "focal_px",
            "min_range",
            "depth_unit",
            "lateral_px",
            "flying_jump",
            "stamp_latency",
            "stamp_jitter",
            "exposure",
        ):
            v = getattr(self, field)
            require(finite(v) and v >= 0, f"sensor.{field}: must be >= 0, got {v!r}")
        require(self.max_range > self.min_range, f"sensor.max_range: must be > min_range, got {self.max_range!r}")
        require(
            finite(self.max_incidence_deg) and 0 < self.max_incidence_deg <= 90,
            f"sensor.max_incidence_deg: must be in (0, 90], got {self.max_incidence_deg!r}",
        )
        for field in ("flying_probability", "hole_fraction"):
            v = getattr(self, field)
            require(finite(v) and 0 <= v <= 1, f"sensor.{field}: must be in [0, 1], got {v!r}")
        require(
            isinstance(self.hole_size_px, int) and self.hole_size_px >= 1,
            f"sensor.hole_size_px: must be an integer >= 1, got {self.hole_size_px!r}",
        )
        require(
            (self.subpixel == 0) or (self.baseline > 0 and self.focal_px > 0),
            "sensor.subpixel: depth noise needs baseline > 0 and focal_px > 0",
        )

    @property
    def is_ideal(self) -> bool:
        """True when the model changes nothing (today's perfect camera)."""
        return self == SensorModel(self.name)

    def depth_rms(self, z: float) -> float:
        """RMS depth error at planar depth ``z`` metres, metres (0 for a sensor without triangulation noise)."""
        if self.subpixel == 0:
            return 0.0
        return z * z * self.subpixel / (self.focal_px * self.baseline)


def _focal(half_width_px: float, hfov_deg: float) -> float:
    """Focal length in pixels of a stream ``2 * half_width_px`` wide with horizontal field of view ``hfov_deg``."""
    return half_width_px / math.tan(math.radians(hfov_deg) / 2)


SENSORS: dict[str, SensorModel] = {
    "ideal": SensorModel("ideal"),
    # Capture during moves (assumptions, docs/experiments/move-capture.md): a stereo frame exposed ~5-8 ms, stamped
    # ~10 +- 3 ms after the joint states it is matched with; a structured-light pattern sequence takes ~0.1 s.
    # Intel RealSense D435: 50 mm stereo baseline, depth FOV 87 x 58 deg, best depth at 848 x 480 (min-Z 0.195 m
    # there), depth unit 1 mm, subpixel 0.08 typical (datasheet rev. 014 and the depth-tuning white paper).
    "realsense-d435": SensorModel(
        "realsense-d435",
        baseline=0.050,
        subpixel=0.08,
        focal_px=_focal(424, 87.0),
        min_range=0.195,
        max_range=3.0,
        depth_unit=0.001,
        lateral_px=0.1,
        max_incidence_deg=75.0,
        flying_probability=0.5,
        hole_fraction=0.01,
        stamp_latency=0.010,
        stamp_jitter=0.003,
        exposure=0.008,
    ),
    # Intel RealSense D405: 18 mm baseline, FOV 87 x 58 deg, 1280 x 720, ideal range 7-50 cm, depth unit 0.1 mm.
    "realsense-d405": SensorModel(
        "realsense-d405",
        baseline=0.018,
        subpixel=0.08,
        focal_px=_focal(640, 87.0),
        min_range=0.07,
        max_range=0.5,
        depth_unit=0.0001,
        lateral_px=0.1,
        max_incidence_deg=75.0,
        flying_probability=0.5,
        hole_fraction=0.01,
        stamp_latency=0.010,
        stamp_jitter=0.003,
        exposure=0.005,
    ),
    # A projector-camera rig like the paper's (a 2048 px wide camera, 70 deg HFOV, projector 120 mm to its side,
    # phase precision 0.05 px): an assumption in the range of desktop structured-light scanners (docs/experiments/sensors.md).
    "structured-light": SensorModel(
        "structured-light",
        baseline=0.12,
        subpixel=0.05,
        focal_px=_focal(1024, 70.0),
        min_range=0.2,
        max_range=0.8,
        depth_unit=0.0,
        lateral_px=0.05,
        max_incidence_deg=70.0,
        flying_probability=0.2,
        hole_fraction=0.005,
        stamp_latency=0.020,
        stamp_jitter=0.005,
        exposure=0.100,
    ),
}
"""Every named sensor preset."""


def sensor_named(name: str) -> SensorModel:
    """The preset called ``name``; ValueError listing the names for an unknown one."""
    try:
        return SENSORS[name]
    except (KeyError, TypeError):
        raise ValueError(f"sensor: unknown sensor {name!r}; known: {', '.join(SENSORS)}") from None
