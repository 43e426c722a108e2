"""Planner configuration: one frozen dataclass per component, nested in ``PlannerConfig``.

Defaults are the paper's where it gives one (resolution 0.01 m, 400 candidates,
beta = 4, T in [5, 50]); every default is documented once, at its field.
Angles are in degrees here (a config edge) and converted to radians in code.
TOML files, the CLI and the REST API use the same names, e.g.
``[voxel] resolution = 0.01`` or ``{"voxel": {"resolution": 0.01}}``.
"""

from __future__ import annotations

import dataclasses
import tomllib
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Literal, TypeVar

from planner.validate import finite, integer, require


@dataclass(frozen=True)
class VoxelConfig:
    """The voxel map over the bounding box B (paper §III-C)."""

    resolution: float = 0.01
    """Voxel edge length, metres (paper: 0.01)."""
    gamma: float = 0.02
    """Radius of the sphere around each frontier voxel that B must cover, metres (paper: gamma)."""
    initial_diagonal_factor: float = 2.0
    """After the first frame B is grown along the view direction until its diagonal is this many times longer (paper: 2)."""
    max_extent: float = 1.0
    """B never grows beyond this edge length, metres (a safety cap; the paper has none)."""
    floor: bool = True
    """Keep B above ``floor_height``: nothing under the plate can be seen. The paper has no floor; without one
    the first-frame growth pushes B, and a ring of frontier voxels, under the plate."""
    floor_height: float = 0.0
    """The floor, metres (the plate top in the turntable frame)."""
    integration: Literal["projective", "raycast"] = "projective"
    """'projective' projects voxel centres into the depth image (fast); 'raycast' is the Amanatides-Woo reference."""

    def __post_init__(self) -> None:
        require(
            finite(self.resolution) and self.resolution > 0, f"voxel.resolution: must be > 0, got {self.resolution!r}"
        )
        require(finite(self.gamma) and self.gamma >= 0, f"voxel.gamma: must be >= 0, got {self.gamma!r}")
        require(
            finite(self.initial_diagonal_factor) and self.initial_diagonal_factor >= 1,
            f"voxel.initial_diagonal_factor: must be >= 1, got {self.initial_diagonal_factor!r}",
        )
        require(
            finite(self.max_extent) and self.max_extent > self.resolution,
            f"voxel.max_extent: must be > resolution, got {self.max_extent!r}",
        )
        require(finite(self.floor_height), f"voxel.floor_height: must be a finite number, got {self.floor_height!r}")
        require(
            self.integration in ("projective", "raycast"),
            f"voxel.integration: 'projective' or 'raycast', got {self.integration!r}",
        )


@dataclass(frozen=True)
class ClusterConfig:
    """GMM clustering of occupied and frontier voxels with BIC model selection (paper §III-D)."""

    t_min: int = 5
    """Fewest Gaussian components tried (paper: 5)."""
    t_max: int = 50
    """Most Gaussian components tried (paper: 50)."""
    search: Literal["fast", "exhaustive"] = "fast"
    """'exhaustive' fits every T in [t_min, t_max]; 'fast' is a warm-started bracketed search (see docs/method.md)."""
    min_points_per_component: int = 4
    """With fewer than t * this voxels, t is capped at n // this (at least 1). See docs/method.md."""
    max_iter: int = 100
    """EM iterations per fit."""
    tol: float = 1e-3
    """EM convergence tolerance on the mean log-likelihood per point."""
    reg_covar_voxels: float = 1.0 / 12.0
    """Added to covariance diagonals, in voxel units squared: 1/12 is the variance of a point uniform in one voxel."""
    seed: int = 0
    """random_state of every fit."""

    def __post_init__(self) -> None:
        require(
            integer(self.t_min) and self.t_min >= 1,
            f"cluster.t_min: must be an integer >= 1, got {self.t_min!r}",
        )
        require(
            integer(self.t_max) and self.t_max >= 1,
            f"cluster.t_max: must be an integer >= 1, got {self.t_max!r}",
        )
        require(self.t_min <= self.t_max, f"cluster.t_min ({self.t_min}) must be <= cluster.t_max ({self.t_max})")
        require(self.search in ("fast", "exhaustive"), f"cluster.search: 'fast' or 'exhaustive', got {self.search!r}")
        require(
            integer(self.min_points_per_component) and self.min_points_per_component >= 1,
            f"cluster.min_points_per_component: must be an integer >= 1, got {self.min_points_per_component!r}",
        )
        require(
            integer(self.max_iter) and self.max_iter >= 1,
            f"cluster.max_iter: must be an integer >= 1, got {self.max_iter!r}",
        )
        require(integer(self.seed) and self.seed >= 0, f"cluster.seed: must be an integer >= 0, got {self.seed!r}")
        require(finite(self.tol) and self.tol > 0, "cluster.tol: must be > 0")
        require(finite(self.reg_covar_voxels) and self.reg_covar_voxels > 0, "cluster.reg_covar_voxels: must be > 0")


@dataclass(frozen=True)
class CandidateConfig:
    """Candidate views on a hemisphere of radius R = d_c + d_b about B's centre (paper §III-B; ``aim``: or about
    the box of the object seen)."""

    count: int = 400
    """N, candidate views in total (paper: 400)."""
    parallels: int = 10
    """alpha, number of equidistant parallels (the paper gives no value)."""
    working_distance: float = 0.35
    """d_c, the camera's working distance, metres."""
    max_range: float = 0.0
    """The depth sensor's farthest return, metres (0: no limit, a perfect camera, the paper's R). When B's far corner,
    ``R + d_b`` from the camera, would lie beyond it, R is cut to ``max(max_range - d_b, d_b + MIN_STANDOFF)``
    (``planner.candidates.sphere_radius``; the cell fills it from its sensor, ``devices.planner_config_for``)."""
    aim: Literal["bbox", "content"] = "bbox"
    """What the candidate sphere is built about (its centre, and d_b its half-diagonal): "bbox", B (the paper), or
    "content", the box of the OCCUPIED and FRONTIER voxels (``Planner.candidate_box``: the object and frontier seen
    so far, without what B's growth along the first view and the gamma-spheres added). The cell sets "content" for
    a sensor with a finite range (``devices.planner_config_for``): with B's centre the bunny's aim lay 10 cm off the
    object, and the range rule put a D405's cameras 5 cm nearer still (docs/experiments/sensors.md)."""
    aim_hold_voxels: int = 1
    """With ``aim = "content"``: after a frame, the sphere stays about the box it was built about while no face of the
    new content box lies more than this many voxels from that box's (``planner.candidates.held_aim``; 0: rebuilt at
    every change). Views then stay the same views from plan to plan while noise moves the box by a voxel, and so do
    the cell's answers about them (its reachability cache is per view): measured with the D435 model (bunny, UR5)
    the plans whose 400 views were new fell from 5-6 to 3 of 10 (docs/experiments/planning-speed.md)."""
    min_elevation_deg: float = 10.0
    """Lowest parallel's elevation above the sphere's centre, degrees (negative: below it; the cell's reachability
    leaves out the views it cannot take). The cell sets -5 for a sensor with a grazing limit
    (``devices.planner_noise.LOW_ELEVATION_DEG``)."""
    max_elevation_deg: float = 85.0
    """Highest parallel's elevation, degrees (90 is the pole, a parallel of length 0)."""

    def __post_init__(self) -> None:
        require(
            integer(self.count) and self.count >= 1,
            f"candidates.count: must be an integer >= 1, got {self.count!r}",
        )
        require(
            integer(self.parallels) and 1 <= self.parallels <= self.count,
            f"candidates.parallels: must be an integer in [1, count], got {self.parallels!r}",
        )
        require(finite(self.working_distance) and self.working_distance > 0, "candidates.working_distance: must be > 0")
        require(
            finite(self.max_range) and self.max_range >= 0,
            f"candidates.max_range: must be >= 0 (0: no limit), got {self.max_range!r}",
        )
        require(self.aim in ("bbox", "content"), f"candidates.aim: 'bbox' or 'content', got {self.aim!r}")
        require(
            integer(self.aim_hold_voxels) and self.aim_hold_voxels >= 0,
            f"candidates.aim_hold_voxels: must be an integer >= 0, got {self.aim_hold_voxels!r}",
        )
        require(
            finite(self.min_elevation_deg, self.max_elevation_deg)
            and -90 < self.min_elevation_deg <= self.max_elevation_deg < 90,
            "candidates: need -90 < min_elevation_deg <= max_elevation_deg < 90",
        )


@dataclass(frozen=True)
class ScoringConfig:
    """The projection score F (paper §III-E)."""

    rank_base: float = 0.5
    """W = rank_base ** r (paper: 0.5)."""
    area: Literal["analytic", "raster"] = "analytic"
    """How L is counted: exact clipped-ellipse area, or rasterising pixel centres (reference)."""

    def __post_init__(self) -> None:
        require(finite(self.rank_base) and 0 < self.rank_base <= 1, "scoring.rank_base: must be in (0, 1]")
        require(self.area in ("analytic", "raster"), f"scoring.area: 'analytic' or 'raster', got {self.area!r}")


@dataclass(frozen=True)
class ZBufferConfig:
    """The visible-frontier score V of the ``projection-zbuffer`` evaluator (``planner.visibility``; not the paper's)."""

    width: int = 40
    """Raster columns per candidate view (40: one raster pixel per 16 x 16 pixels of a 640 x 480 camera; 80 x 60
    measured no better and 4x slower, docs/experiments/zbuffer.md)."""
    height: int = 30
    """Raster rows per candidate view."""
    depth_tolerance_voxels: float = 0.0
    """A pixel shows frontier when its nearest frontier ellipsoid is at most this many voxels behind the nearest
    occupied one (0: strictly in front; 1 and 3 measured worse early, docs/experiments/zbuffer.md)."""
    measure: Literal["pixels", "voxels"] = "voxels"
    """What a frontier pixel is worth: its ellipsoid's voxel count over the pixels the ellipsoid covers in that view
    ("voxels": V = sum over frontier ellipsoids of n_points x visible fraction), or 1 ("pixels": V = visible frontier
    pixels; measured slightly lower area under the coverage curve, docs/experiments/zbuffer.md)."""
    hidden_weight: float = 0.0
    """A frontier pixel hidden behind an occupied ellipsoid counts this much (0: only frontier in view counts)."""
    frontier_decay: float = 1.0
    """A frontier voxel's weight is ``frontier_decay ** k`` after it stayed FRONTIER through k new frames; a frontier
    ellipsoid weighs the mean of its voxels (1: every frontier pixel counts the same)."""

    def __post_init__(self) -> None:
        require(self.measure in ("pixels", "voxels"), f"zbuffer.measure: 'pixels' or 'voxels', got {self.measure!r}")
        require(
            finite(self.hidden_weight) and 0 <= self.hidden_weight <= 1,
            f"zbuffer.hidden_weight: must be in [0, 1], got {self.hidden_weight!r}",
        )
        require(
            finite(self.frontier_decay) and 0 < self.frontier_decay <= 1,
            f"zbuffer.frontier_decay: must be in (0, 1], got {self.frontier_decay!r}",
        )
        for name in ("width", "height"):
            n = getattr(self, name)
            require(integer(n) and 1 <= n <= 1024, f"zbuffer.{name}: must be an integer in [1, 1024], got {n!r}")
        require(
            finite(self.depth_tolerance_voxels) and self.depth_tolerance_voxels >= 0,
            f"zbuffer.depth_tolerance_voxels: must be >= 0, got {self.depth_tolerance_voxels!r}",
        )


@dataclass(frozen=True)
class PartitionConfig:
    """Global longitude partitions (paper §III-F)."""

    sectors: int = 4
    """beta, number of longitude sectors (paper: 4)."""
    offset_deg: float = 0.0
    """Longitude where sector 0 starts, degrees."""
    revisit_deg: float = 30.0
    """Candidates within this angle (seen from B's centre) of a view already taken are not proposed again,
    degrees; never less than half the candidate spacing (0: just that, the paper's rule). A departure: about
    half the camera's horizontal field of view, measured +0.3 points of final coverage over 24 scenes
    (docs/method.md). When it would leave no candidate, only the half spacing applies."""

    def __post_init__(self) -> None:
        require(
            integer(self.sectors) and self.sectors >= 1,
            f"partitions.sectors: must be an integer >= 1, got {self.sectors!r}",
        )
        require(finite(self.offset_deg), "partitions.offset_deg: must be finite")
        require(
            finite(self.revisit_deg) and 0 <= self.revisit_deg < 180,
            f"partitions.revisit_deg: must be in [0, 180), got {self.revisit_deg!r}",
        )


@dataclass(frozen=True)
class SelectionConfig:
    """How the next view is chosen among the eligible candidates."""

    move_cost_weight: float = 0.0
    """Trades F against the move's duration: the view maximising F / max|F| - weight * t / max t (both over the
    eligible views; t the move seconds the caller gives per candidate). 0, the default, is the paper's greedy
    rule (largest F, no move cost asked); MA-SCVP's movement-cost variants do the same trade."""

    def __post_init__(self) -> None:
        require(
            finite(self.move_cost_weight) and self.move_cost_weight >= 0,
            f"selection.move_cost_weight: must be >= 0, got {self.move_cost_weight!r}",
        )


@dataclass(frozen=True)
class TourConfig:
    """The ``tour`` planner (``planner.tour``): a set of views covering the predicted frontier, ordered by move time."""

    horizon: int = 6
    """Most views in one tour (the set cover stops here): the receding horizon."""
    min_gain: float = 0.03
    """The cover stops when the best next view would add less than this fraction of the frontier all eligible views
    see together."""
    width: int = 160
    """Raster columns of the visibility z-buffer per candidate (160 x 120: about two raster pixels per voxel at the
    working distance for a 640 x 480 camera, so the 3 x 3 minimum that closes the gaps between projected voxel
    centres widens an occluder by half a voxel, not a whole one, and a frontier seen through a narrow gap stays
    seen; 80 x 60 measured 0.4 views more to 95 % of the ceiling, docs/experiments/tour.md)."""
    height: int = 120
    """Raster rows of the visibility z-buffer."""
    depth_tolerance_voxels: float = 1.0
    """A frontier voxel is seen when it is at most this many voxels behind the nearest voxel in its raster pixel."""
    order: Literal["tsp", "rate", "gain"] = "rate"
    """Which view of the cover runs next (the rest follow in the shortest order from it): "tsp" the first of the
    shortest open path (LKH), "rate" the first of the order with the largest area under the predicted coverage
    against robot time (``planner.tour.rate_order``), "gain" the view with the largest gain."""
    overhead_seconds: float = 0.0
    """Seconds each view costs besides its move (capture and plan), in the "rate" order."""
    score: Literal["frontier", "projection"] = "frontier"
    """What the plan optimises: "frontier" the set cover of the frontier voxels the views see, ordered by move time
    (``horizon``, ``min_gain``, ``order``); "projection" the paper's score F (GMM ellipsoids, ``planner.scoring``),
    and the next view is the one with the shortest move from the current state among the best by F that score at
    least (1 - ``slack``) x the best F (``planner.tour.near_best``: moves timed as the cell would make them, every
    plate angle and IK branch)."""
    lazy_reach: bool = True
    """Skip the plan's reachability pass over every candidate: only the views the tour times (its cover, or with
    ``score = "projection"`` the views near the best F) are checked, by their moves from the current state (inf:
    unreachable, left out and the cover made again); the others stay unchecked (no move time in the table).
    False: every candidate checked first, as for the other planners (the same cover; 0.3-1 s more per cold plan)."""
    slack: float = 0.1
    """With ``score = "projection"``: how far below the best F (a fraction of it) a view may score and still be
    chosen for a shorter move."""
    near_views: int = 8
    """With ``score = "projection"``: how many reachable views (best F first) have their moves timed (about 20 ms
    of IK each); with ``opening = "ring"``: how many of the ring's views (most frontier first) are timed."""
    opening: Literal["none", "ring"] = "ring"
    """The scan's first plans: "ring" (default) a turntable scanner's ring first (``planner.tour.ring_view``): the
    plans after the first and second views each take a low view near one of the two azimuths ``ring_spread_deg``
    either side of the scan's first view (about the object) that no view taken since is near, the shortest move
    (timed as the cell would make it) among those that see the most frontier; then the tour. "none": the tour from
    the first plan on (docs/experiments/tour.md measures both). With ``score = "frontier"``
    only: ``score = "projection"`` chooses by its own rule from the first plan."""
    ring_spread_deg: float = 120.0
    """With ``opening = "ring"``: the ring's two azimuths, degrees either side of the first view's."""
    ring_max_elevation_deg: float = 30.0
    """With ``opening = "ring"``: the highest elevation (degrees, about the object's box centre) of a ring view."""
    ring_tolerance_deg: float = 30.0
    """With ``opening = "ring"``: how far in azimuth (degrees) a view may be from a ring azimuth and still be its view
    (a view taken that near closes it)."""
    ring_share: float = 0.5
    """With ``opening = "ring"``: a ring view must see at least this fraction of the frontier voxels the best ring
    view sees; of those, the ``near_views`` that see the most are timed and the shortest move wins."""
    lookahead: bool = True
    """With ``opening = "ring"``: the ring's first plan names the other side's ring views (``TourPlan.then``), and the
    move to its view takes the plate angle and arm configuration whose move plus the quickest move on to one of
    them is shortest (``Cell.move_to(then=...)``), not the quickest move alone."""
    cover_max_elevation_deg: float = 25.0
    """The cover takes views at most this high (degrees, about the object's box centre) while any of them sees
    frontier (then any eligible view); 90 = no limit. Measured with the ring opening, after it (docs/experiments/tour.md)."""
    path_coverage: bool = False
    """When the cell captures during moves: the cover counts, for the views whose moves are estimated (``path.*``),
    the frontier the frames of the move from the current state see too, so the next view may be chosen for its way
    there (``planner.tour.TourEvaluator._with_paths``). Off: on the development meshes with the D435 it made the
    tour's robot time to 95 % longer, not shorter (docs/experiments/scan-while-moving.md). No effect without
    capture during moves."""

    def __post_init__(self) -> None:
        require(
            integer(self.horizon) and 1 <= self.horizon <= 50,
            f"tour.horizon: an integer in [1, 50], got {self.horizon!r}",
        )
        require(
            finite(self.min_gain) and 0 <= self.min_gain < 1, f"tour.min_gain: must be in [0, 1), got {self.min_gain!r}"
        )
        for name in ("width", "height"):
            n = getattr(self, name)
            require(integer(n) and 1 <= n <= 1024, f"tour.{name}: must be an integer in [1, 1024], got {n!r}")
        require(
            finite(self.depth_tolerance_voxels) and self.depth_tolerance_voxels >= 0,
            f"tour.depth_tolerance_voxels: must be >= 0, got {self.depth_tolerance_voxels!r}",
        )
        require(self.order in ("tsp", "rate", "gain"), f"tour.order: 'tsp', 'rate' or 'gain', got {self.order!r}")
        require(self.score in ("frontier", "projection"), f"tour.score: 'frontier' or 'projection', got {self.score!r}")
        require(isinstance(self.lazy_reach, bool), f"tour.lazy_reach: true or false, got {self.lazy_reach!r}")
        require(finite(self.slack) and 0 <= self.slack < 1, f"tour.slack: must be in [0, 1), got {self.slack!r}")
        require(
            integer(self.near_views) and 1 <= self.near_views <= 400,
            f"tour.near_views: an integer in [1, 400], got {self.near_views!r}",
        )
        require(
            finite(self.overhead_seconds) and self.overhead_seconds >= 0,
            f"tour.overhead_seconds: must be >= 0, got {self.overhead_seconds!r}",
        )
        require(self.opening in ("none", "ring"), f"tour.opening: 'none' or 'ring', got {self.opening!r}")
        require(
            finite(self.ring_spread_deg) and 0 < self.ring_spread_deg <= 180,
            f"tour.ring_spread_deg: must be in (0, 180], got {self.ring_spread_deg!r}",
        )
        require(
            finite(self.ring_max_elevation_deg) and -90 <= self.ring_max_elevation_deg <= 90,
            f"tour.ring_max_elevation_deg: must be in [-90, 90], got {self.ring_max_elevation_deg!r}",
        )
        require(
            finite(self.ring_tolerance_deg) and 0 < self.ring_tolerance_deg <= 90,
            f"tour.ring_tolerance_deg: must be in (0, 90], got {self.ring_tolerance_deg!r}",
        )
        require(
            finite(self.ring_share) and 0 <= self.ring_share <= 1,
            f"tour.ring_share: must be in [0, 1], got {self.ring_share!r}",
        )
        require(isinstance(self.lookahead, bool), f"tour.lookahead: true or false, got {self.lookahead!r}")
        require(
            finite(self.cover_max_elevation_deg) and -90 <= self.cover_max_elevation_deg <= 90,
            f"tour.cover_max_elevation_deg: must be in [-90, 90], got {self.cover_max_elevation_deg!r}",
        )
        require(isinstance(self.path_coverage, bool), f"tour.path_coverage: true or false, got {self.path_coverage!r}")


@dataclass(frozen=True)
class PathConfig:
    """The ``path`` planner (``planner.paths``), and the moves the ``tour`` counts with ``tour.path_coverage``: the
    next view chosen for the frontier it and the frames along its move see, per second of robot time."""

    sample_hz: float = 2.5
    """Frames per second the planner places along each estimated move (the frames the cell will take are counted at
    this rate, whatever rate it captures at: 2.5 Hz covered within 3 % of 5 Hz, docs/experiments/scan-while-moving.md)."""
    candidates: int = 12
    """How many views have their moves estimated: those that see the most frontier (each costs the cell's search
    for the move's target, a few ms of IK with the UR5)."""
    sweep_views: int = 6
    """And up to this many views of the lowest parallel, spread around the object: their moves turn the plate with
    the camera low, the sweep that sees the most."""
    overhead_seconds: float = 1.0
    """Seconds each view costs besides its move (capture, plan, motion planning) in the rate frontier / (move +
    overhead): larger favours longer moves that see more."""
    unknown_stride: int = 2
    """The gain also counts the unknown voxels the view and its move's frames see (a z-buffer of the occupied ones):
    one of every this-many in each axis (0: frontier only). The frontier is a thin rim after the first view, so a
    long sweep past the unseen side would look barely better than a short move; the unknown space it looks into
    tells them apart."""

    def __post_init__(self) -> None:
        require(
            finite(self.sample_hz) and 0 < self.sample_hz <= 30,
            f"path.sample_hz: must be in (0, 30], got {self.sample_hz!r}",
        )
        require(
            integer(self.candidates) and 1 <= self.candidates <= 400,
            f"path.candidates: an integer in [1, 400], got {self.candidates!r}",
        )
        require(
            integer(self.sweep_views) and 0 <= self.sweep_views <= 100,
            f"path.sweep_views: an integer in [0, 100], got {self.sweep_views!r}",
        )
        require(
            finite(self.overhead_seconds) and self.overhead_seconds >= 0,
            f"path.overhead_seconds: must be >= 0, got {self.overhead_seconds!r}",
        )
        require(
            integer(self.unknown_stride) and 0 <= self.unknown_stride <= 16,
            f"path.unknown_stride: an integer in [0, 16], got {self.unknown_stride!r}",
        )


@dataclass(frozen=True)
class TerminationConfig:
    """When Algorithm 1 stops: any of these."""

    max_views: int = 10
    """Stop after this many captured views (paper: 10)."""
    growth_threshold: float = 0.0
    """Stop when the point count grows by less than this fraction in one view; 0 disables (paper's table: < 0.1 after view 5)."""
    stop_without_frontier: bool = True
    """Stop when no frontier voxel is left."""

    def __post_init__(self) -> None:
        require(
            integer(self.max_views) and self.max_views >= 1,
            f"termination.max_views: must be an integer >= 1, got {self.max_views!r}",
        )
        require(
            finite(self.growth_threshold) and self.growth_threshold >= 0, "termination.growth_threshold: must be >= 0"
        )


@dataclass(frozen=True)
class PreprocessConfig:
    """Cleaning a frame before it is registered and integrated."""

    crop_margin: float = 0.03
    """Points farther than this outside B are dropped, metres."""
    workspace_radius: float = 0.3
    """Before B exists (first frame): keep points within this radius of the turntable axis, metres."""
    workspace_height: float = 0.6
    """Before B exists: keep points below this height, metres."""
    plate_clearance: float = 0.002
    """Points below this height (the turntable plate) are removed, metres."""
    outlier_radius: float = 0.0075
    """Radius outlier removal: the neighbourhood radius, metres (three 2.5 mm down-sampling cells)."""
    outlier_min_neighbors: int = 2
    """Radius outlier removal: keep a point only with at least this many others within ``outlier_radius``
    (0 disables). Isolated specks go; every point of a sampled surface, its edges and thin parts stay."""
    downsample: float = 0.0025
    """Voxel down-sampling edge length for the accumulated cloud, metres (0 disables)."""
    move_point_radius: float = 0.01
    """Capture during moves: a view's points replace the cloud points of frames taken during moves within this
    distance, and a move frame's points within it of a view's are left out, metres (0: only within a down-sampling
    cell). A still view is measured better than a move frame (blur, a late stamp); the voxel map takes both
    (planner.cloud)."""
    support_min_points: int = 0
    """Opt-in (0 = off, the paper): drop the points of every cell of ``support_voxel`` that holds fewer than this
    many of the frame's points, so sparse returns (a real sensor's flying pixels at depth edges, a veil in mid-air
    that the radius filter keeps) neither grow B nor become occupied. The cell sets it for a noisy sensor
    (``devices.planner_noise``); a surface at 0.6 m puts about 100 points in a 1 cm cell."""
    support_voxel: float = 0.01
    """Edge of the cells ``support_min_points`` counts in, metres (the voxel map's resolution)."""

    def __post_init__(self) -> None:
        for name in (
            "crop_margin",
            "workspace_radius",
            "workspace_height",
            "plate_clearance",
            "outlier_radius",
            "downsample",
            "move_point_radius",
            "support_voxel",
        ):
            v = getattr(self, name)
            require(finite(v) and v >= 0, f"preprocess.{name}: must be >= 0, got {v!r}")
        require(
            integer(self.outlier_min_neighbors) and self.outlier_min_neighbors >= 0,
            "preprocess.outlier_min_neighbors: must be an integer >= 0",
        )
        require(
            integer(self.support_min_points) and self.support_min_points >= 0,
            f"preprocess.support_min_points: must be an integer >= 0, got {self.support_min_points!r}",
        )
        require(
            self.support_min_points == 0 or self.support_voxel > 0,
            "preprocess.support_voxel: must be > 0 when support_min_points is set",
        )


@dataclass(frozen=True)
class RegistrationConfig:
    """Point-to-plane ICP of each frame to the accumulated cloud, with an acceptance gate."""

    enabled: bool = True
    """Run ICP from the second frame on."""
    max_correspondence: float = 0.01
    """ICP correspondence distance, metres."""
    max_iterations: int = 30
    """ICP iterations."""
    min_fitness: float = 0.3
    """Reject the ICP result when fewer than this fraction of points found a partner."""
    max_rmse: float = 0.0025
    """Reject the ICP result when the inlier point-to-plane RMSE exceeds this, metres (correct fits: 0.4-1.9 mm)."""
    max_correction: float = 0.03
    """Reject corrections that move the camera farther than this, metres."""

    def __post_init__(self) -> None:
        for name in ("max_correspondence", "max_rmse", "max_correction"):
            v = getattr(self, name)
            require(finite(v) and v > 0, f"registration.{name}: must be > 0, got {v!r}")
        require(0 <= self.min_fitness <= 1, "registration.min_fitness: must be in [0, 1]")
        require(
            integer(self.max_iterations) and self.max_iterations >= 1,
            f"registration.max_iterations: must be an integer >= 1, got {self.max_iterations!r}",
        )


@dataclass(frozen=True)
class NoiseConfig:
    """The depth sensor's noise as the planner should expect it (``planner.noise``): sets the plate band and the
    ICP gate. The defaults (0) describe a perfect sensor and leave the paper's fixed thresholds alone; the cell
    fills them from its sensor model (``devices.sensors.noise_config``)."""

    depth_std: float = 0.0
    """Depth noise independent of range (std), metres."""
    depth_z2: float = 0.0
    """Depth noise growing with range: std = depth_z2 * z**2 at planar depth z (triangulation), 1/metres."""
    plate_sigmas: float = 3.5
    """Points within this many noise stds (projected on the vertical) of the plate top are plate, not object."""
    icp_sigmas: float = 3.0
    """ICP's rmse gate is at least this many times the expected residual (sqrt(2) x the depth std at the frame's
    median depth)."""
    fit_plate: bool = False
    """Fit the plate's plane in each frame (robust least squares on the points near z = 0) and measure the band
    from it: with calibration error the plate seen through the reported pose is tilted and offset by millimetres
    (a 0.3 degree hand-eye error lifts its rim by 1 mm). Off (the paper): the plate is z = 0."""
    plate_fit_window: float = 0.01
    """Points within this of z = 0 are the plate fit's candidates, metres."""
    plate_fit_max_tilt_deg: float = 90.0
    """With ``fit_plate``: only points whose surface normal (from the depth image's neighbours) lies within this
    angle of the vertical are the fit's candidates, degrees (90: every point, as before). The plate's rim (its
    vertical side) is then no candidate: from a low view a sensor with a grazing limit sees the rim and not the
    top, and the fit, on the rim alone, put the plane up to 4 mm low or tilted it 2.5 degrees (the rim's top edge
    stayed in the cloud, a 0.2 m arc of wrong points)."""
    flying_jump: float = 0.0
    """Opt-in (0 = off): drop the pixels at depth discontinuities, where a 4-neighbour's depth differs by more
    than this fraction of the pixel's (a real sensor's flying pixels sit there). Their rays carve like holes."""
    dropout_fill_px: int = 0
    """Opt-in (0 = off, the paper: a pixel without depth is free space to the sensor's range): a pixel without
    depth within this many pixels of one with depth is a dropout (a hole, a shadow of the second viewpoint, a
    grazing surface), not free space: its ray is free only up to the nearest depth around it and unknown beyond.
    Only pixels far from every return (the void around the object) stay free."""

    def __post_init__(self) -> None:
        for name in ("depth_std", "depth_z2", "plate_sigmas", "icp_sigmas", "plate_fit_window"):
            v = getattr(self, name)
            require(finite(v) and v >= 0, f"noise.{name}: must be >= 0, got {v!r}")
        require(isinstance(self.fit_plate, bool), f"noise.fit_plate: must be true or false, got {self.fit_plate!r}")
        require(
            finite(self.plate_fit_max_tilt_deg) and 0 < self.plate_fit_max_tilt_deg <= 90,
            f"noise.plate_fit_max_tilt_deg: must be in (0, 90], got {self.plate_fit_max_tilt_deg!r}",
        )
        require(finite(self.flying_jump) and self.flying_jump >= 0, "noise.flying_jump: must be >= 0")
        require(
            integer(self.dropout_fill_px) and 0 <= self.dropout_fill_px <= 100,
            f"noise.dropout_fill_px: must be an integer in [0, 100], got {self.dropout_fill_px!r}",
        )

    @property
    def exact(self) -> bool:
        """True for a noise-free sensor whose plate is where the kinematics say (nothing to adapt)."""
        return (
            self.depth_std == 0
            and self.depth_z2 == 0
            and not self.fit_plate
            and self.flying_jump == 0
            and self.dropout_fill_px == 0
        )


@dataclass(frozen=True)
class PlannerConfig:
    """Everything the planner needs; nested per component."""

    voxel: VoxelConfig = field(default_factory=VoxelConfig)
    cluster: ClusterConfig = field(default_factory=ClusterConfig)
    candidates: CandidateConfig = field(default_factory=CandidateConfig)
    scoring: ScoringConfig = field(default_factory=ScoringConfig)
    zbuffer: ZBufferConfig = field(default_factory=ZBufferConfig)
    partitions: PartitionConfig = field(default_factory=PartitionConfig)
    selection: SelectionConfig = field(default_factory=SelectionConfig)
    tour: TourConfig = field(default_factory=TourConfig)
    path: PathConfig = field(default_factory=PathConfig)
    termination: TerminationConfig = field(default_factory=TerminationConfig)
    preprocess: PreprocessConfig = field(default_factory=PreprocessConfig)
    registration: RegistrationConfig = field(default_factory=RegistrationConfig)
    noise: NoiseConfig = field(default_factory=NoiseConfig)

    def to_dict(self) -> dict[str, Any]:
        return dataclasses.asdict(self)

    @staticmethod
    def from_dict(data: dict[str, Any]) -> PlannerConfig:
        """Build from a nested dict; any subset of fields; unknown names are an error."""
        return from_dict(PlannerConfig, data)

    @staticmethod
    def from_journal(data: dict[str, Any]) -> PlannerConfig:
        """Build from the config a journal recorded: as :meth:`from_dict`, but the settings of :data:`REMOVED`
        (which older builds wrote into every journal) are dropped, so a journal written before their removal
        still resumes. Any other unknown name is still an error."""
        return from_dict(PlannerConfig, without_removed(data))

    @staticmethod
    def from_toml(path: str | Path) -> PlannerConfig:
        with open(path, "rb") as fh:
            try:
                data = tomllib.load(fh)
            except tomllib.TOMLDecodeError as exc:
                raise ValueError(f"{path}: invalid TOML ({exc})") from None
        return PlannerConfig.from_dict(data)

    def replace(self, **sections: Any) -> PlannerConfig:
        """Override fields by nested dict, e.g. ``replace(voxel={"resolution": 0.005})``."""
        return merge(self, sections)


C = TypeVar("C")

REMOVED: dict[str, str] = {
    "voxel.frontier_max_looks": "retiring frontier voxels looked into n times measured neutral (docs/experiments/departures.md)",
    "scoring.max_incidence_deg": "the incidence-aware score measured no better (docs/experiments/sensors.md)",
    "partitions.stall_growth": "leaving a stalled sector measured neutral (docs/experiments/departures.md)",
}
"""Settings earlier builds had, by dotted name, and why they went. A journal that carries one still loads
(:meth:`PlannerConfig.from_journal`, :func:`without_removed`: ignored); a user who sets one (TOML, REST, a
flag) is told that it was removed and why."""


def without_removed(data: dict[str, Any], prefix: str = "") -> dict[str, Any]:
    """A copy of the nested config dict ``data`` without the settings of :data:`REMOVED` (for journals)."""
    if not isinstance(data, dict):
        return data
    return {
        key: without_removed(value, f"{prefix}{key}.") if isinstance(value, dict) else value
        for key, value in data.items()
        if f"{prefix}{key}" not in REMOVED
    }


def from_dict(cls: type[C], data: dict[str, Any], prefix: str = "") -> C:
    """Instantiate dataclass ``cls`` from ``data``, recursing into nested dataclasses."""
    return merge(cls(), data, prefix)


def merge(base: C, data: dict[str, Any], prefix: str = "") -> C:
    """A copy of dataclass instance ``base`` with the fields in ``data`` replaced (recursively)."""
    if not isinstance(data, dict):
        raise ValueError(f"{prefix.rstrip('.') or 'config'}: expected a table/object, got {type(data).__name__}")
    fields = {f.name: f for f in dataclasses.fields(base)}  # type: ignore[arg-type]
    changes: dict[str, Any] = {}
    for key, value in data.items():
        if key not in fields:
            if f"{prefix}{key}" in REMOVED:
                raise ValueError(f"{prefix}{key}: removed setting ({REMOVED[prefix + key]})")
            known = ", ".join(sorted(fields))
            raise ValueError(f"{prefix}{key}: unknown setting (known: {known})")
        current = getattr(base, key)
        if dataclasses.is_dataclass(current) and not isinstance(current, type):
            changes[key] = merge(current, value, f"{prefix}{key}.")
        else:
            if isinstance(current, bool) and not isinstance(value, bool):
                raise ValueError(f"{prefix}{key}: expected true/false, got {value!r}")
            if isinstance(current, int | float) and not isinstance(current, bool) and isinstance(value, bool):
                raise ValueError(f"{prefix}{key}: expected a number, got {value!r}")
            if (
                isinstance(current, int)
                and not isinstance(current, bool)
                and isinstance(value, float)
                and value.is_integer()
            ):
                value = int(value)
            if isinstance(current, float) and isinstance(value, int) and not isinstance(value, bool):
                value = float(value)
            if isinstance(current, int | float) and not isinstance(value, int | float):
                raise ValueError(f"{prefix}{key}: expected a number, got {value!r}")
            changes[key] = value
    try:
        return dataclasses.replace(base, **changes)  # type: ignore[type-var]
    except ValueError as exc:
        msg = str(exc)
        raise ValueError(msg if msg.startswith(prefix) or not prefix else f"{msg}") from None
