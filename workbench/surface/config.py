"""``SurfaceConfig``: how the surface is fused, cut and closed. Every default is measured (docs/experiments/surface.md)."""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass
from typing import TYPE_CHECKING, Literal

from planner.validate import finite, integer, require

if TYPE_CHECKING:
    from devices.config import CameraConfig

SurfaceMethod = Literal["tsdf", "poisson"]


@dataclass(frozen=True)
class SurfaceConfig:
    """The reconstruction's settings (lengths in metres)."""

    method: SurfaceMethod = "tsdf"
    """'tsdf': the fused surface as marching cubes gives it (open where the scan saw nothing, e.g. the bottom);
    'poisson': watertight, a screened Poisson surface of the fused surface's points with the bottom closed on
    the plate plane. TSDF is the default: Poisson's precision at 5 mm is 0.97 on the bunny (it invents
    surface where no view looked) and its update takes 3 s; TSDF: 0.15 s of CPU, precision 1.00."""
    voxel_size: float = 0.0025
    """TSDF voxel edge. 2.5 mm: F@5mm within 0.3 points of 2 mm on four objects at 60 % of the triangles and
    time; 3 mm loses up to 10 points of F@2mm (docs/experiments/surface.md)."""
    truncation_voxels: float = 3.0
    """TSDF truncation distance in voxels (7.5 mm at 2.5 mm voxels): 4 loses up to 2.4 points of F@2mm on thin
    parts (the dragon), 6 up to 28 (the mug); 2 loses 0.3 points of F@5mm on average and 0.9 on the truck (its
    F@5mm then 2.5 points below its cloud's). A real sensor takes 2 (:func:`surface_config_for`)."""
    weight_threshold: float = 0.5
    """Marching cubes keeps voxels whose weight (views that saw them) is above this: 0.5 keeps what one view saw;
    1.0 (two views) loses 1.3 points of F@5mm on the bunny at 10 views."""
    support_voxels: int = 1
    """Marching-cubes vertices with no fused point within this many voxels (per axis) are dropped: the fins a
    TSDF grows behind silhouette edges, up to the truncation distance long (0 keeps them). On the lion F@5mm
    0.932 -> 0.980, precision@5mm 0.894 -> 0.988; on the bunny no change (-0.03 points)."""
    depth_max: float = 3.0
    """Depths beyond this are not fused."""
    plate_clearance: float = 0.002
    """Surface below this height is the plate, cut away (the planner's ``preprocess.plate_clearance``)."""
    fuse_plate: bool = True
    """Fuse the plate's pixels inside the object's box (True) or drop every pixel below ``plate_clearance``:
    fusing them keeps the base of the walls (F@5mm +0.7 points on the bunny, +1.4 on the box)."""
    box_margin: float = 0.01
    """The object's box (from the frames' points above the plate, or given) grown by this much; pixels whose
    point falls outside are not fused and the surface outside is cut."""
    workspace_radius: float = 0.3
    """Points farther than this from the turntable axis are never the object (the planner's first-frame rule)."""
    workspace_height: float = 0.6
    """Points higher than this are never the object."""
    poisson_depth: int = 8
    """Octree depth of the screened Poisson solve (cells of about 1 mm over a 0.2 m object)."""
    poisson_density_quantile: float = 0.0
    """Poisson vertices whose support density is in this lowest fraction are trimmed (0: keep every vertex, the
    result stays watertight)."""

    def __post_init__(self) -> None:
        require(self.method in ("tsdf", "poisson"), f"surface.method: 'tsdf' or 'poisson', got {self.method!r}")
        for name in ("voxel_size", "truncation_voxels", "weight_threshold", "depth_max"):
            v = getattr(self, name)
            require(finite(v) and v > 0, f"surface.{name}: must be > 0, got {v!r}")
        for name in ("plate_clearance", "box_margin", "workspace_radius", "workspace_height"):
            v = getattr(self, name)
            require(finite(v) and v >= 0, f"surface.{name}: must be >= 0, got {v!r}")
        require(
            integer(self.support_voxels) and self.support_voxels >= 0,
            f"surface.support_voxels: an integer >= 0, got {self.support_voxels!r}",
        )
        require(
            integer(self.poisson_depth) and 4 <= self.poisson_depth <= 12,
            f"surface.poisson_depth: an integer in [4, 12], got {self.poisson_depth!r}",
        )
        q = self.poisson_density_quantile
        require(finite(q) and 0 <= q < 1, f"surface.poisson_density_quantile: in [0, 1), got {q!r}")

    @property
    def truncation(self) -> float:
        """The truncation distance, metres."""
        return self.voxel_size * self.truncation_voxels


REAL_SENSOR_TRUNCATION_VOXELS = 2.0
"""The truncation of a sensor with depth noise or flying pixels. The fins a TSDF grows behind silhouette edges are
up to the truncation long, and such a sensor's scattered returns support them past the support filter: with the
RealSense D435 and typical calibration, 3 voxels left precision@5mm at 0.88 on the lion and 0.91 / 0.96 on the
lion / camel of seed 1; 2 voxels: 0.94, 0.97, 0.98 at 1 point of recall (docs/experiments/surface.md)."""


def surface_config_for(camera: CameraConfig, base: SurfaceConfig | None = None) -> SurfaceConfig:
    """``base`` (default ``SurfaceConfig()``) for the scans of ``camera``: a sensor with depth noise or flying
    pixels (any preset but 'ideal', or ``depth_noise_std`` > 0) fuses with :data:`REAL_SENSOR_TRUNCATION_VOXELS`;
    the ideal camera keeps ``base`` as it is. Like ``devices.planner_noise.planner_config_for`` for the planner."""
    from devices.sensors.presets import sensor_named

    base = base if base is not None else SurfaceConfig()
    sensor = sensor_named(camera.sensor)
    noisy = camera.depth_noise_std > 0 or sensor.subpixel > 0 or sensor.flying_probability > 0
    if not noisy:
        return base
    return dataclasses.replace(base, truncation_voxels=REAL_SENSOR_TRUNCATION_VOXELS)
