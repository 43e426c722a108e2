"""The board's small picture of a seat's scene: its accumulated cloud seen obliquely, coloured by height."""

from __future__ import annotations

import io

import numpy as np
from numpy.typing import NDArray

__all__ = ["cloud_picture"]

BACKGROUND = (30, 34, 42)
LOW, HIGH = np.array([70, 130, 220]), np.array([250, 200, 90])
"""Colours of the lowest and the highest points (height along z, linear in between)."""


def cloud_picture(points_world: NDArray[np.float64], size: int = 160) -> bytes:
    """A ``size`` x ``size`` PNG of ``points_world`` (N, 3), metres, seen from the front right and above (the
    default 3D view's direction), scaled to fit; points nearer the viewer drawn last. An empty cloud is the
    background alone."""
    from PIL import Image

    image = np.zeros((size, size, 3), np.uint8)
    image[:] = BACKGROUND
    pts = np.asarray(points_world, dtype=np.float64).reshape(-1, 3)
    pts = pts[np.isfinite(pts).all(axis=1)]
    if len(pts):
        yaw, pitch = np.deg2rad(-40.0), np.deg2rad(30.0)
        c, s = np.cos(yaw), np.sin(yaw)
        x = c * pts[:, 0] - s * pts[:, 1]
        depth = s * pts[:, 0] + c * pts[:, 1]  # away from the viewer
        y = np.cos(pitch) * pts[:, 2] - np.sin(pitch) * depth
        near = -(np.cos(pitch) * depth + np.sin(pitch) * pts[:, 2])
        span = max(float(np.ptp(x)), float(np.ptp(y)), 1e-6)
        margin = 0.08 * size
        scale = (size - 2 * margin) / span
        u = ((x - (x.min() + x.max()) / 2) * scale + size / 2).astype(int)
        v = (size / 2 - (y - (y.min() + y.max()) / 2) * scale).astype(int)
        z = pts[:, 2]
        t = (z - z.min()) / max(float(np.ptp(z)), 1e-6)
        colour = (LOW[None, :] * (1 - t[:, None]) + HIGH[None, :] * t[:, None]).astype(np.uint8)
        order = np.argsort(near)  # far first: the near points overwrite them
        for du in (0, 1):  # 2x2 dots: a sparse first view still reads as a shape
            for dv in (0, 1):
                uu, vv = np.clip(u[order] + du, 0, size - 1), np.clip(v[order] + dv, 0, size - 1)
                image[vv, uu] = colour[order]
    out = io.BytesIO()
    Image.fromarray(image).save(out, format="PNG", optimize=True)
    return out.getvalue()
