"""The second viewpoint of a triangulating sensor: a point has depth only if the other imager (stereo) or the
projector (structured light) sees it too, so the far side of every occluding edge loses a band of data.

One more ray cast, from the second viewpoint to every point the camera saw, with the camera's own open3d
``RaycastingScene``.
"""

from __future__ import annotations

from typing import Any

import numpy as np
from numpy.typing import NDArray

OCCLUSION_TOLERANCE = 0.001
"""A second-viewpoint ray that stops within this of the point (metres, plus 0.2 % of its length) reached it."""


def second_view_visible(scene: Any, origin: NDArray[np.float64], points: NDArray[np.float64]) -> NDArray[np.bool_]:
    """(N,) bool: whether the straight line from ``origin`` (3,) to each of ``points`` (N, 3) (same frame as the
    scene) is clear: the first surface the ray meets is the point itself."""
    import open3d as o3d

    if len(points) == 0:
        return np.zeros(0, dtype=bool)
    d = points - origin[None, :]
    length = np.linalg.norm(d, axis=1)
    rays = np.empty((len(points), 6), dtype=np.float32)
    rays[:, :3] = origin.astype(np.float32)
    rays[:, 3:] = (d / np.maximum(length, 1e-12)[:, None]).astype(np.float32)
    t_hit = scene.cast_rays(o3d.core.Tensor.from_numpy(rays))["t_hit"].numpy().astype(np.float64)
    return ~(t_hit < length - (OCCLUSION_TOLERANCE + 0.002 * length))
