"""A depth sensor's per-pixel effects on a rendered depth image, as small functions over arrays.

Each takes the image as (H, W) float32 planar z-depth with 0 for "no return" and a ``numpy.random.Generator``
(deterministic from the camera's seed). :func:`apply_effects` runs them in the order a device makes them:
grazing incidence and range first (no signal), then flying pixels at depth edges (mixed returns), the
depth noise, dropout holes and finally the depth unit's rounding.
"""

from __future__ import annotations

import math

import numpy as np
from numpy.typing import NDArray

from devices.sensors.presets import SensorModel

Depth = NDArray[np.float32]


def grazing(cos_incidence: NDArray[np.float32], max_incidence_deg: float) -> NDArray[np.bool_]:
    """(H, W) bool: True where the viewing ray meets the surface farther than ``max_incidence_deg`` from its
    normal. cos_incidence: (H, W) |cos| of the angle between the ray and the surface normal."""
    return cos_incidence < math.cos(math.radians(max_incidence_deg))


def in_range(depth: Depth, min_range: float, max_range: float) -> Depth:
    """``depth`` with returns outside [min_range, max_range] set to 0."""
    keep = (depth >= min_range) & (depth <= max_range)
    return np.where(keep, depth, np.float32(0.0)).astype(np.float32)


def discontinuities(depth: Depth, jump: float) -> NDArray[np.bool_]:
    """(H, W) bool: pixels with a return whose 4-neighbour (also with a return) differs by more than ``jump``
    times the pixel's depth: the two sides of a depth edge."""
    valid = depth > 0
    out = np.zeros(depth.shape, dtype=bool)
    for axis in (0, 1):
        a = np.take(depth, np.arange(depth.shape[axis] - 1), axis=axis)
        b = np.take(depth, np.arange(1, depth.shape[axis]), axis=axis)
        va = np.take(valid, np.arange(depth.shape[axis] - 1), axis=axis)
        vb = np.take(valid, np.arange(1, depth.shape[axis]), axis=axis)
        edge = va & vb & (np.abs(a - b) > jump * np.minimum(a, b))
        if axis == 0:
            out[:-1] |= edge
            out[1:] |= edge
        else:
            out[:, :-1] |= edge
            out[:, 1:] |= edge
    return out


def flying_pixels(depth: Depth, probability: float, jump: float, rng: np.random.Generator) -> Depth:
    """Mixed returns at depth edges: each pixel of :func:`discontinuities`, with ``probability``, takes a depth
    uniformly between its own and its farthest-differing 4-neighbour's (the pixel saw both sides)."""
    edges = discontinuities(depth, jump)
    if probability <= 0 or not np.any(edges):
        return depth
    padded = np.pad(depth, 1, mode="edge")
    h, w = depth.shape
    neighbours = np.stack(
        [padded[:-2, 1:-1], padded[2:, 1:-1], padded[1:-1, :-2], padded[1:-1, 2:]]
    )  # (4, H, W): up, down, left, right
    diff = np.where(neighbours > 0, np.abs(neighbours - depth[None]), 0.0)
    other = np.take_along_axis(neighbours, diff.argmax(axis=0)[None], axis=0)[0]
    v, u = np.nonzero(edges)
    pick = rng.random(len(v)) < probability
    v, u = v[pick], u[pick]
    t = rng.random(len(v)).astype(np.float32)
    out = depth.copy()
    out[v, u] = depth[v, u] + t * (other[v, u] - depth[v, u])
    assert out.shape == (h, w)
    return out


def depth_noise(depth: Depth, sensor: SensorModel, extra_std: float, rng: np.random.Generator) -> Depth:
    """Zero-mean Gaussian depth noise of std ``sqrt(sensor.depth_rms(z)**2 + extra_std**2)`` on every return."""
    valid = depth > 0
    z = depth[valid].astype(np.float64)
    sigma = np.sqrt((z * z * sensor.subpixel / max(sensor.focal_px * sensor.baseline, 1e-12)) ** 2 + extra_std**2)
    if not np.any(sigma > 0):
        return depth
    out = depth.copy()
    out[valid] = (z + rng.normal(0.0, 1.0, len(z)) * sigma).astype(np.float32)
    return out


def holes(shape: tuple[int, int], fraction: float, size_px: int, rng: np.random.Generator) -> NDArray[np.bool_]:
    """(H, W) bool dropout mask: square blobs of ``size_px`` placed at random until about ``fraction`` of the
    image is covered (blobs may overlap, so the share is at most ``fraction``)."""
    h, w = shape
    mask = np.zeros(shape, dtype=bool)
    if fraction <= 0:
        return mask
    count = round(fraction * h * w / (size_px * size_px))
    vs = rng.integers(0, max(1, h - size_px + 1), count)
    us = rng.integers(0, max(1, w - size_px + 1), count)
    for v, u in zip(vs, us, strict=True):
        mask[v : v + size_px, u : u + size_px] = True
    return mask


def quantise(depth: Depth, unit: float) -> Depth:
    """``depth`` rounded to multiples of ``unit`` metres (0 = unchanged); a return rounded to 0 stays 0."""
    if unit <= 0:
        return depth
    return (np.round(depth.astype(np.float64) / unit) * unit).astype(np.float32)


def apply_effects(
    depth: Depth,
    cos_incidence: NDArray[np.float32],
    sensor: SensorModel,
    extra_std: float,
    rng: np.random.Generator,
) -> Depth:
    """Every per-pixel effect of ``sensor`` on a clean (H, W) depth image (0 = no return): grazing incidence,
    range, flying pixels, depth noise (plus ``extra_std`` metres, the cell's ``depth_noise_std``), holes,
    quantisation, and the range once more (noise may push a return out of it)."""
    out = np.where(grazing(cos_incidence, sensor.max_incidence_deg), np.float32(0.0), depth).astype(np.float32)
    out = in_range(out, sensor.min_range, sensor.max_range)
    out = flying_pixels(out, sensor.flying_probability, sensor.flying_jump, rng)
    out = depth_noise(out, sensor, extra_std, rng)
    out[holes(out.shape, sensor.hole_fraction, sensor.hole_size_px, rng)] = 0.0  # type: ignore[index]
    out = quantise(out, sensor.depth_unit)
    return in_range(out, sensor.min_range, sensor.max_range)
