"""planner.noise: the plate band and the ICP gate follow the expected depth noise; a perfect sensor keeps the
paper's fixed thresholds."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from planner.config import NoiseConfig, PreprocessConfig, RegistrationConfig
from planner.noise import (
    depth_std,
    dropouts_filled,
    fit_plate,
    plane_moved,
    plate_heights,
    plate_plane,
    registration_for,
    unknown_beyond_range,
    vertical_cosines,
    without_flying_pixels,
)
from planner.types import DepthFrame, Intrinsics, Pose, VoxelClass
from planner.voxel_map import observe_projective

K = Intrinsics(64, 48, 60.0, 60.0, 31.5, 23.5)
DOWN = Pose(np.array([[1.0, 0.0, 0.0], [0.0, -1.0, 0.0], [0.0, 0.0, -1.0]]), np.array([0.0, 0.0, 0.5]))


def plane_frame(depth: float = 0.5) -> DepthFrame:
    return DepthFrame(np.full((K.height, K.width), depth, dtype=np.float32), DOWN, K)


def test_perfect_sensor_keeps_the_fixed_band_and_gate() -> None:
    frame = plane_frame()
    assert np.all(plate_heights(frame, PreprocessConfig(), NoiseConfig()) == PreprocessConfig().plate_clearance)
    config = RegistrationConfig()
    assert registration_for(frame, config, NoiseConfig()) is config


def test_band_follows_the_noise_at_the_range() -> None:
    noise = NoiseConfig(depth_z2=0.004)  # 1 mm at 0.5 m
    heights = plate_heights(plane_frame(), PreprocessConfig(), noise)
    # looking straight down: the whole depth error is vertical; the centre pixel's ray is vertical
    assert heights.max() == pytest.approx(3.5 * 0.001, rel=1e-3)
    assert np.all(heights >= PreprocessConfig().plate_clearance)
    assert float(depth_std(np.array([0.25]), noise)[0]) == pytest.approx(0.00025)


def test_icp_gate_rises_with_the_noise() -> None:
    noise = NoiseConfig(depth_std=0.002)
    gates = registration_for(plane_frame(), RegistrationConfig(), noise)
    assert gates.max_rmse == pytest.approx(3.0 * np.sqrt(2) * 0.002)
    # the correspondence distance (and with it the normals' neighbourhood, 3x it) stays the paper's: widened to
    # 3x the gate (19 mm at 1 mm noise), ICP paired neighbouring surfaces and shifted D435 clouds by 2-3 mm
    assert gates.max_correspondence == RegistrationConfig().max_correspondence
    quiet = registration_for(plane_frame(), RegistrationConfig(), NoiseConfig(depth_std=0.0001))
    assert quiet.max_rmse == RegistrationConfig().max_rmse  # never below the paper's gate


def test_bad_noise_config() -> None:
    with pytest.raises(ValueError, match=r"noise\.depth_std: must be >= 0"):
        NoiseConfig(depth_std=-1.0)


def step_frame() -> DepthFrame:
    """Left half at 0.4 m, right half at 0.5 m; a 3 x 3 hole in the left half."""
    depth = np.full((K.height, K.width), 0.5, dtype=np.float32)
    depth[:, : K.width // 2] = 0.4
    depth[10:13, 10:13] = 0.0
    return DepthFrame(depth, DOWN, K)


def test_flying_pixel_filter_drops_both_sides_of_a_depth_edge_only() -> None:
    frame = step_frame()
    out = without_flying_pixels(frame, 0.01)
    dropped = (frame.depth > 0) & (out.depth == 0)
    cols = np.unique(np.nonzero(dropped)[1])
    assert cols.tolist() == [K.width // 2 - 1, K.width // 2]
    assert without_flying_pixels(frame, 0.0) is frame


def test_dropouts_carve_to_the_nearest_depth_around_them() -> None:
    frame = step_frame()
    filled = dropouts_filled(frame, 4)
    assert np.all(filled.depth[10:13, 10:13] == np.float32(0.4))  # the hole is a surface of unknown beyond
    depth = np.zeros((K.height, K.width), dtype=np.float32)
    depth[0, 0] = 0.3
    void = DepthFrame(depth, DOWN, K)
    far = dropouts_filled(void, 4)
    assert far.depth[20, 40] == 0  # far from every return: still free space
    assert far.depth[3, 3] == np.float32(0.3)
    assert dropouts_filled(frame, 0) is frame


def test_dropout_filling_is_the_whole_image_minimum_filter() -> None:
    """dropouts_filled filters only the returns' box widened by the radius: the same depths as the window minimum
    over the whole image (returns at the image's edges and corners, one return, scattered returns, none)."""
    from scipy.ndimage import minimum_filter

    def reference(depth: np.ndarray, radius: int) -> np.ndarray:
        hole = depth == 0
        near = minimum_filter(
            np.where(hole, np.float32(np.inf), depth), size=2 * radius + 1, mode="constant", cval=np.inf
        )
        return np.where(hole & np.isfinite(near), near, depth).astype(np.float32)

    rng = np.random.default_rng(4)
    cases = []
    for _ in range(30):
        depth = np.zeros((K.height, K.width), dtype=np.float32)
        n = int(rng.integers(1, 40))
        v, u = rng.integers(0, K.height, n), rng.integers(0, K.width, n)
        depth[v, u] = rng.uniform(0.2, 0.9, n).astype(np.float32)
        cases.append(depth)
    edges = np.zeros((K.height, K.width), dtype=np.float32)
    edges[0, 5], edges[K.height - 1, K.width - 1], edges[7, 0] = 0.5, 0.6, 0.7
    cases += [edges, step_frame().depth, np.zeros((K.height, K.width), dtype=np.float32)]
    for depth in cases:
        frame = DepthFrame(depth, DOWN, K)
        for radius in (1, 3, 4, 9):
            assert np.array_equal(dropouts_filled(frame, radius).depth, reference(depth, radius))


def test_no_return_is_free_only_up_to_the_sensor_range() -> None:
    """A camera 0.8 m above the floor looking down, a 0.5 m sensor: the floor returns nothing. The paper's rule
    carves the whole column EMPTY (for good); with the range, voxels whose far side is beyond 0.5 m of depth
    (z < 0.3 m) stay UNKNOWN. A pixel the carve frame cleared on purpose (the plate: it had a return) stays free."""
    eye = Pose(DOWN.rotation, np.array([0.0, 0.0, 0.8]))
    measured = DepthFrame(np.zeros((K.height, K.width), dtype=np.float32), eye, K)
    lower, shape = np.array([-0.05, -0.05, 0.0]), (10, 10, 60)  # z from 0 to 0.6 m, 1 cm voxels
    paper = observe_projective(measured, lower, 0.01, shape)
    assert np.all(paper[4:6, 4:6] == VoxelClass.EMPTY)
    carve = unknown_beyond_range(measured, measured, 0.5)
    assert np.all(carve.depth == np.float32(0.5))
    obs = observe_projective(carve, lower, 0.01, shape)
    column = obs[5, 5]  # the voxel column under the camera, k = 0 at z 0..1 cm
    assert np.all(column[:29] == VoxelClass.UNKNOWN)  # depth 0.8 - z beyond 0.5 m somewhere in the voxel
    assert np.all(column[30:] == VoxelClass.EMPTY)
    plate = DepthFrame(np.full((K.height, K.width), 0.8, dtype=np.float32), eye, K)  # returns, cleared as plate
    assert unknown_beyond_range(measured, plate, 0.5) is measured
    assert unknown_beyond_range(measured, measured, 0.0) is measured  # no range given: the paper's rule


def test_plate_fit_ignores_the_rim_and_the_foot() -> None:
    """A low view: a thin strip of plate top (raised 2 mm and tilted 0.2 degrees by a calibration error), the
    plate's vertical rim seen head-on (z from -10 to 0 mm at r = 0.2 m, more points than the top) and an object's
    foot (z 0-10 mm). The fit finds the top; a least-squares start on the whole window found a plane below it."""
    rng = np.random.default_rng(0)
    slope = np.tan(np.radians(0.2))
    top_xy = np.column_stack([rng.uniform(0.15, 0.2, 3000), rng.uniform(-0.05, 0.05, 3000)])
    top = np.column_stack([top_xy, 0.002 + slope * top_xy[:, 0] + rng.normal(0, 0.0003, 3000)])
    angle = rng.uniform(-0.3, 0.3, 6000)
    rim = np.column_stack([0.2 * np.cos(angle), 0.2 * np.sin(angle), rng.uniform(-0.01, 0.0, 6000)])
    foot = np.column_stack([rng.uniform(-0.05, 0.05, (3000, 2)), rng.uniform(0.0, 0.01, 3000)])
    a, b, c = fit_plate(np.concatenate([top, rim, foot]), 0.01, 0.3)
    for x in (0.15, 0.175, 0.2):  # within 0.5 mm of the top over the whole strip
        for y in (-0.05, 0.05):
            assert a * x + b * y + c == pytest.approx(0.002 + slope * x, abs=0.0005)
    assert np.all(fit_plate(rim[:100], 0.01, 0.3) == 0)  # too few points: z = 0


SMALL_K = Intrinsics(160, 120, 150.0, 150.0, 79.5, 59.5)


def plate_frame(eye: tuple[float, float, float], top_height: float, with_top: bool) -> DepthFrame:
    """A depth frame (exact ray casts) of the turntable plate seen from ``eye`` looking at the origin: its top, a
    disk of radius 0.2 m at ``top_height`` (left out with ``with_top`` False, as a sensor whose grazing limit the
    view exceeds returns nothing there), and its rim, the vertical side r = 0.2 m from the top down to -20 mm."""
    pose = Pose.look_at(np.array(eye, dtype=np.float64), np.zeros(3))
    v, u = np.mgrid[0 : SMALL_K.height, 0 : SMALL_K.width].astype(np.float64)
    rays = np.stack([(u - SMALL_K.cx) / SMALL_K.fx, (v - SMALL_K.cy) / SMALL_K.fy, np.ones_like(u)], axis=-1)
    d = rays @ pose.rotation.T  # world directions with camera z = 1: the ray parameter is the planar depth
    o = pose.translation
    depth = np.full(u.shape, np.inf)
    if with_top:
        t = (top_height - o[2]) / d[..., 2]
        p = o + t[..., None] * d
        depth = np.where((t > 0) & (np.hypot(p[..., 0], p[..., 1]) <= 0.2), t, depth)
    a = d[..., 0] ** 2 + d[..., 1] ** 2  # the cylinder r = 0.2: the nearer root
    b = 2 * (o[0] * d[..., 0] + o[1] * d[..., 1])
    c = o[0] ** 2 + o[1] ** 2 - 0.04
    disc = b * b - 4 * a * c
    t = (-b - np.sqrt(np.maximum(disc, 0.0))) / (2 * a)
    z = o[2] + t * d[..., 2]
    rim = (disc > 0) & (t > 0) & (z <= top_height) & (z >= -0.02)
    depth = np.where(rim & (t < depth), t, depth)
    return DepthFrame(np.where(np.isfinite(depth), depth, 0.0).astype(np.float32), pose, SMALL_K)


def test_vertical_cosines_tell_the_plate_top_from_its_rim() -> None:
    frame = plate_frame((0.45, 0.0, 0.1), 0.0, with_top=True)
    cos = vertical_cosines(frame)
    p = frame.points_world
    r = np.hypot(p[:, 0], p[:, 1])
    inner = (r < 0.18) & (cos > 0)  # the top away from the rim (pixels within the stencil of an edge are 0)
    rim = (p[:, 2] < -0.007) & (p[:, 2] > -0.013) & (cos > 0)  # the rim's middle: its stencil stays on it
    assert np.count_nonzero(inner) > 1000 and np.count_nonzero(rim) > 100
    assert np.all(cos[inner] > 0.999)
    assert np.all(cos[rim] < 0.05)


def test_vertical_cosines_equal_the_normals_of_the_world_points_with_holes_and_a_tilted_camera() -> None:
    """The camera-frame cross product against the direct one: every world point's neighbours, their cross product,
    its vertical share (the formula before the speed-up), on a noisy frame with holes seen from an oblique pose."""
    rng = np.random.default_rng(4)
    depth = (0.5 + 0.02 * rng.standard_normal((K.height, K.width))).astype(np.float32)
    depth[rng.random(depth.shape) < 0.3] = 0.0
    pose = Pose.look_at(np.array([0.3, -0.2, 0.35]), np.array([0.0, 0.02, 0.05]))
    frame = DepthFrame(depth, pose, K)
    s = 3
    world = np.zeros((K.height, K.width, 3))
    world[depth > 0] = frame.points_world
    du = world[s:-s, 2 * s :] - world[s:-s, : -2 * s]
    dv = world[2 * s :, s:-s] - world[: -2 * s, s:-s]
    n = np.cross(du, dv)
    d = depth
    ok = (d[s:-s, 2 * s :] > 0) & (d[s:-s, : -2 * s] > 0) & (d[2 * s :, s:-s] > 0) & (d[: -2 * s, s:-s] > 0)
    expected = np.zeros(depth.shape)
    expected[s:-s, s:-s] = np.where(ok, np.abs(n[..., 2]) / np.maximum(np.linalg.norm(n, axis=-1), 1e-300), 0.0)
    got = vertical_cosines(frame, s)
    np.testing.assert_allclose(got, expected[depth > 0], atol=1e-12)
    assert np.count_nonzero(got) > 200 and np.ptp(got[got > 0]) > 0.5  # real spread, not all zero or all one
    at = np.flatnonzero(rng.random(len(got)) < 0.3)  # some points only, the border's among them
    rows, cols = np.nonzero(depth > 0)
    assert np.any((rows[at] < s) | (cols[at] >= K.width - s))
    np.testing.assert_array_equal(vertical_cosines(frame, s, at=at), got[at])


def test_a_low_view_without_the_plate_top_fits_no_plane() -> None:
    """From 3 degrees above the plate a sensor with a grazing limit returns the rim and not the top. The rim alone
    is no plane to fit: with every point a candidate the fit put a tilted plane through it; with only points on a
    near-horizontal surface there are none, and the plate is z = 0. Where the top is in view (20 degrees), both
    fit the top (raised 1.5 mm as a calibration error would)."""
    low = plate_frame((0.5, 0.0, 0.03), 0.0015, with_top=False)
    rim_fit = fit_plate(low.points_world, 0.01, 0.3)
    assert np.any(rim_fit != 0)  # the failure: the rim taken for the plate
    noise = NoiseConfig(depth_z2=0.001, fit_plate=True, plate_fit_max_tilt_deg=30.0)
    heights = plate_heights(low, PreprocessConfig(), noise)
    flat = plate_heights(low, PreprocessConfig(), dataclasses.replace(noise, fit_plate=False))
    np.testing.assert_array_equal(heights, flat)  # no fit: the band above z = 0
    high = plate_frame((0.45, 0.0, 0.17), 0.0015, with_top=True)
    horizontal = vertical_cosines(high) >= np.cos(np.radians(30.0))
    a, b, c = fit_plate(high.points_world, 0.01, 0.3, horizontal)
    assert (a, b) == pytest.approx((0.0, 0.0), abs=1e-4) and c == pytest.approx(0.0015, abs=1e-4)


def test_a_plane_moves_with_the_points_a_registration_moves() -> None:
    """plane_moved: points on the plane z = a x + b y + c, moved by a rigid correction, lie on the moved plane."""
    rng = np.random.default_rng(7)
    plane = np.array([0.01, -0.02, 0.0015])
    xy = rng.uniform(-0.2, 0.2, (50, 2))
    points = np.column_stack([xy, plane[0] * xy[:, 0] + plane[1] * xy[:, 1] + plane[2]])
    angle = np.radians(2.0)
    axis = np.array([0.3, -0.5, 0.8]) / np.linalg.norm([0.3, -0.5, 0.8])
    k = np.array([[0, -axis[2], axis[1]], [axis[2], 0, -axis[0]], [-axis[1], axis[0], 0]])
    rotation = np.eye(3) + np.sin(angle) * k + (1 - np.cos(angle)) * k @ k
    correction = Pose(rotation, np.array([0.003, -0.002, 0.004]))
    moved = correction.apply(points)
    a, b, c = plane_moved(plane, correction)
    np.testing.assert_allclose(moved[:, 2], a * moved[:, 0] + b * moved[:, 1] + c, atol=1e-12)
    assert c != pytest.approx(plane[2], abs=1e-3)  # it did move (by the correction's 4 mm)
    np.testing.assert_allclose(plane_moved(plane, Pose(np.eye(3), np.zeros(3))), plane)


def test_plate_heights_from_a_given_plane_equal_the_frames_own_fit() -> None:
    """plate_heights(plane=plate_plane(frame)) is plate_heights(frame): the planner fits once per frame and hands
    the measured frame's plane to the dropout-filled one it carves."""
    frame = plate_frame((0.45, 0.0, 0.17), 0.0015, with_top=True)
    noise = NoiseConfig(depth_z2=0.001, fit_plate=True, plate_fit_max_tilt_deg=30.0)
    plane = plate_plane(frame, PreprocessConfig(), noise)
    assert plane[2] == pytest.approx(0.0015, abs=1e-4)
    np.testing.assert_array_equal(
        plate_heights(frame, PreprocessConfig(), noise, plane), plate_heights(frame, PreprocessConfig(), noise)
    )
    assert np.all(plate_plane(frame, PreprocessConfig(), dataclasses.replace(noise, fit_plate=False)) == 0)
