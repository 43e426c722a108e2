"""The calibration target: spheres of known radius on thin posts standing on the plate.

A depth-only camera sees a sphere as a cap whose centre a least-squares fit recovers to a fraction of the depth
noise; three or more spheres at different heights fix the target's pose in every frame. The default target is
four 40 mm balls (table-tennis balls are round to about 0.1 mm) on 8 mm dowels glued into a plate-sized disc;
docs/hardware.md ("Commissioning a cell") gives the drawing.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import trimesh
from numpy.typing import NDArray

from planner.types import BoundingBox
from planner.validate import finite, require


@dataclass(frozen=True, eq=False)
class SphereTarget:
    """radius: of every sphere, metres. centres_table: (K, 3) float64 the sphere centres in the table frame as
    built (the fit estimates them; these are its start and tell the spheres apart). post_radius: the posts from
    the plate top (z = 0) to each sphere's bottom, metres (0 = floating spheres, simulation only)."""

    radius: float
    centres_table: NDArray[np.float64]
    post_radius: float = 0.004

    def __post_init__(self) -> None:
        require(finite(self.radius) and self.radius > 0, f"target.radius: must be > 0, got {self.radius!r}")
        c = np.asarray(self.centres_table, dtype=np.float64)
        require(c.ndim == 2 and c.shape[1] == 3 and len(c) >= 3, f"target.centres_table: need (K>=3, 3), got {c.shape}")
        require(bool(np.all(np.isfinite(c))), "target.centres_table: has non-finite entries")
        gaps = np.linalg.norm(c[:, None] - c[None], axis=2) + np.eye(len(c)) * 1e9
        require(float(gaps.min()) > 2 * self.radius + 0.02, "target.centres_table: spheres closer than 2 cm apart")
        require(bool(np.all(c[:, 2] - self.radius > 0)), "target.centres_table: a sphere reaches below the plate top")
        require(np.linalg.matrix_rank(c[1:] - c[0], tol=1e-3) >= 2, "target.centres_table: the centres lie on one line")
        require(finite(self.post_radius) and 0 <= self.post_radius < self.radius, "target.post_radius: in [0, radius)")
        object.__setattr__(self, "centres_table", c)

    @property
    def count(self) -> int:
        return len(self.centres_table)

    @property
    def centre(self) -> NDArray[np.float64]:
        """(3,) the middle of the sphere centres, table frame: where the calibration views look."""
        return self.centres_table.mean(axis=0)

    def box(self) -> BoundingBox:
        """The target's box, table frame (the arm keeps clear of it)."""
        lower = self.centres_table.min(axis=0) - self.radius
        upper = self.centres_table.max(axis=0) + self.radius
        lower[2] = 0.0
        return BoundingBox(lower, upper)

    def mesh(self, subdivisions: int = 4) -> trimesh.Trimesh:
        """The target as a triangle mesh, table frame (the simulated camera renders it)."""
        parts: list[trimesh.Trimesh] = []
        for c in self.centres_table:
            parts.append(trimesh.creation.icosphere(subdivisions=subdivisions, radius=self.radius).apply_translation(c))
            height = float(c[2] - self.radius)
            if self.post_radius > 0 and height > 1e-4:
                post = trimesh.creation.cylinder(radius=self.post_radius, height=height, sections=24)
                parts.append(post.apply_translation((c[0], c[1], 0.5 * height)))
        mesh = trimesh.util.concatenate(parts)
        assert isinstance(mesh, trimesh.Trimesh)
        return mesh


DEFAULT_TARGET = SphereTarget(
    radius=0.02,
    centres_table=np.array(
        [[0.12, 0.0, 0.06], [-0.06, 0.104, 0.10], [-0.06, -0.104, 0.14], [0.0, 0.0, 0.18]], dtype=np.float64
    ),
)
"""Four 40 mm balls, three 12 cm from the axis at heights 6, 10, 14 cm (120 degrees apart) and one on the axis at
18 cm: not coplanar, far enough from the axis for its tilt to show."""
