"""preprocess: crop to B or the workspace, plate removal, radius outliers; voxel_downsample."""

from __future__ import annotations

import numpy as np
import pytest

from planner.config import PreprocessConfig
from planner.preprocess import preprocess, remove_radius_outliers, voxel_downsample
from planner.types import BoundingBox

NO_OUTLIERS = PreprocessConfig(outlier_min_neighbors=0, downsample=0.0)


def _grid(lo: float, hi: float, n: int, z: float = 0.05) -> np.ndarray:
    g = np.linspace(lo, hi, n)
    x, y = np.meshgrid(g, g, indexing="ij")
    return np.column_stack([x.ravel(), y.ravel(), np.full(x.size, z)])


def test_crop_to_bbox_with_margin() -> None:
    bbox = BoundingBox(np.array([-0.05, -0.05, 0.0]), np.array([0.05, 0.05, 0.1]))
    pts = np.array(
        [
            [0.0, 0.0, 0.05],  # inside
            [0.079, 0.0, 0.05],  # 0.029 outside in x: within the 0.03 margin
            [0.081, 0.0, 0.05],  # 0.031 outside: dropped
            [0.0, -0.079, 0.129],  # within the margin in y and z
            [0.0, 0.0, 0.131],  # too high
            [0.0, 0.0, 0.001],  # inside B but on the plate: dropped
        ]
    )
    out = preprocess(pts, bbox, NO_OUTLIERS)
    np.testing.assert_array_equal(out, pts[[0, 1, 3]])
    assert out.dtype == np.float64


def test_workspace_cylinder_before_b_exists() -> None:
    cfg = PreprocessConfig(
        outlier_min_neighbors=0, workspace_radius=0.3, workspace_height=0.6, plate_clearance=0.002, downsample=0.0
    )
    pts = np.array(
        [
            [0.2, 0.2, 0.1],  # radius 0.283: kept
            [0.25, 0.2, 0.1],  # radius 0.320: dropped
            [0.0, 0.0, 0.59],  # kept
            [0.0, 0.0, 0.61],  # above the workspace
            [0.1, 0.0, 0.0019],  # the plate
            [0.1, 0.0, 0.0021],  # just above the plate
            [0.1, 0.0, -0.05],  # below the plate
        ]
    )
    np.testing.assert_array_equal(preprocess(pts, None, cfg), pts[[0, 2, 5]])


def test_isolated_points_are_removed_and_the_surface_is_kept() -> None:
    surface = _grid(-0.05, 0.05, 41)  # 2.5 mm grid
    stray = np.array(
        [[0.0, 0.0, 0.2], [0.1, 0.1, 0.12], [-0.08, 0.02, 0.3], [-0.08, 0.021, 0.3]]
    )  # the last two: a pair
    pts = np.concatenate([surface, stray])
    out = preprocess(pts, None, PreprocessConfig(outlier_radius=0.0075, outlier_min_neighbors=2, downsample=0.0))
    np.testing.assert_array_equal(out, surface)
    # disabled: the strays stay
    assert len(preprocess(pts, None, NO_OUTLIERS)) == len(pts)


def test_surface_edges_and_thin_parts_are_kept() -> None:
    """The reason for the radius rule: on a clean sampled surface nothing is an outlier.

    A square, a 2.5 mm-wide strip (one row of points) and a lone thin wire: the default
    filter keeps every point. Statistical removal (mean 16-NN distance > mean + 2.5 std)
    drops the wire and the square's corners: surface the voxel map would then miss.
    """
    square = _grid(-0.05, 0.05, 41)
    wire = np.column_stack([np.full(30, 0.1), np.linspace(-0.03, 0.0425, 30), np.full(30, 0.05)])
    pts = np.concatenate([square, wire])
    out = preprocess(pts, None, PreprocessConfig(downsample=0.0))
    np.testing.assert_array_equal(out, pts)
    # what the statistical rule would have done, for the record
    from scipy.spatial import KDTree

    dist, _ = KDTree(pts).query(pts, k=17)
    mean = dist[:, 1:].mean(axis=1)
    assert np.count_nonzero(mean > mean.mean() + 2.5 * mean.std()) > 0


def test_remove_radius_outliers_counts_others_within_the_radius() -> None:
    # points on a line 1 apart; a point 5 away from everything
    line = np.column_stack([np.arange(10.0), np.zeros(10), np.zeros(10)])
    pts = np.concatenate([line, [[9.0, 5.0, 0.0]]])
    np.testing.assert_array_equal(remove_radius_outliers(pts, radius=1.0, min_neighbors=1), line)
    # two neighbours within 1: the two ends of the line have only one
    np.testing.assert_array_equal(remove_radius_outliers(pts, radius=1.0, min_neighbors=2), line[1:-1])
    # radius inclusive, large enough: nothing goes
    assert len(remove_radius_outliers(pts, radius=5.0, min_neighbors=1)) == 11
    assert len(remove_radius_outliers(np.zeros((0, 3)), radius=1.0, min_neighbors=1)) == 0
    with pytest.raises(ValueError, match="min_neighbors: must be an integer >= 1"):
        remove_radius_outliers(pts, radius=1.0, min_neighbors=0)
    with pytest.raises(ValueError, match="radius: must be >= 0"):
        remove_radius_outliers(pts, radius=float("nan"), min_neighbors=1)


def test_preprocess_downsamples_before_outlier_removal() -> None:
    pts = _grid(-0.01, 0.01, 50)  # 0.4 mm spacing, far denser than PreprocessConfig.downsample
    cfg = PreprocessConfig(outlier_min_neighbors=0, downsample=0.0025)
    out = preprocess(pts, None, cfg)
    # the 20 mm square spans lattice cells -4..4 of 2.5 mm per axis: 9 x 9 centroids
    assert len(out) == 81
    assert np.allclose(np.sort(np.unique(np.round(out[:, 0], 6)))[[0, -1]], [-0.00877551, 0.01], atol=1e-6)
    assert np.array_equal(out, voxel_downsample(pts, 0.0025))


@pytest.mark.parametrize(
    ("points", "pattern"),
    [
        (np.array([[0.0, 0.0, np.nan]]), r"points_world: 1 non-finite"),
        (np.array([[np.inf, 0.0, 0.1], [0.0, 0.0, 0.1]]), r"points_world: 1 non-finite"),
        (np.zeros((4, 2)), r"points_world: expected shape \(N, 3\)"),
    ],
)
def test_bad_input(points: np.ndarray, pattern: str) -> None:
    with pytest.raises(ValueError, match=pattern):
        preprocess(points, None, PreprocessConfig())


def test_empty_input_gives_empty_output() -> None:
    assert preprocess(np.zeros((0, 3)), None, PreprocessConfig()).shape == (0, 3)


def test_voxel_downsample_centroids() -> None:
    pts = np.array(
        [
            [0.001, 0.001, 0.001],
            [0.003, 0.003, 0.001],  # same 5 mm voxel as the first
            [0.006, 0.0, 0.0],  # next voxel in x
            [-0.001, 0.0, 0.0],  # voxel -1 in x
            [0.0061, 0.0041, 0.0049],
        ]
    )
    out = voxel_downsample(pts, 0.005)
    expected = np.array([[-0.001, 0.0, 0.0], [0.002, 0.002, 0.001], [0.00605, 0.00205, 0.00245]])
    np.testing.assert_allclose(out, expected, atol=1e-15)


def test_voxel_downsample_density_and_edge_cases() -> None:
    rng = np.random.default_rng(0)
    pts = rng.random((20000, 3)) * 0.1  # a 10 cm cube
    out = voxel_downsample(pts, 0.01)
    assert len(out) == 1000  # every 1 cm voxel is hit
    assert np.all(np.abs(out - (np.floor(out / 0.01) * 0.01 + 0.005)) < 0.004)  # centroids near voxel centres
    np.testing.assert_array_equal(voxel_downsample(pts, 0.0), pts)
    assert voxel_downsample(np.zeros((0, 3)), 0.01).shape == (0, 3)
    with pytest.raises(ValueError, match="size: must be >= 0"):
        voxel_downsample(pts, -0.01)
    far = np.array([[0.0, 0.0, 0.0], [1e6, 1e6, 1e6]])  # a huge lattice: falls back to unique rows
    np.testing.assert_array_equal(voxel_downsample(far, 1e-6), far)


def test_radius_inliers_equal_counting_the_whole_ball() -> None:
    """The k-nearest shortcut keeps exactly the points the ball count keeps: random clouds, clouds on a lattice
    (neighbours exactly at the radius), duplicated points, radius 0."""
    from scipy.spatial import KDTree

    from planner.preprocess import radius_inliers

    rng = np.random.default_rng(0)
    flipped = 0
    for trial in range(120):
        n = int(rng.integers(1, 300))
        p = rng.random((n, 3)) * rng.choice([0.01, 0.05, 0.2])
        if trial % 3 == 0:
            p = np.round(p / 0.0025) * 0.0025
        if trial % 5 == 0 and n > 2:
            p[: n // 3] = p[0]
        r = float(rng.choice([0.0, 0.0025, 0.005, 0.0075, 0.01]))
        m = int(rng.integers(1, 6))
        ball = np.asarray(KDTree(p).query_ball_point(p, r=r, return_length=True)) - 1 >= m
        np.testing.assert_array_equal(radius_inliers(p, r, m), ball)
        flipped += int(ball.sum()) not in (0, n)
    assert flipped > 40  # most cases keep some points and drop others: the comparison has teeth
