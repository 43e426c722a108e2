"""The voxel map: classes from synthetic depth frames, final-ness, growth of B, rollback, projective vs raycast.

Scenes are rendered analytically (axis-aligned boxes, spheres). Most tests use a camera
at y = -0.4 looking along world +y (image x = world x, image y = world -z), a box whose
front face is at y = 0.0042 and a wall at y = 0.1043 behind it; the odd offsets keep
surfaces off the 0.01 m lattice planes. "Lattice index" n means the voxel [n, n+1) * 0.01.
"""

from __future__ import annotations

import numpy as np
import pytest
from scipy import ndimage
from scipy.spatial import KDTree

import planner.voxel_map as vm
from planner.config import VoxelConfig
from planner.raycast import pixel_rays, ray_observations
from planner.types import DepthFrame, Intrinsics, Pose, VoxelClass
from planner.voxel_map import VoxelMap, observe_projective

E, O, U, F, N = VoxelClass.EMPTY, VoxelClass.OCCUPIED, VoxelClass.UNKNOWN, VoxelClass.FRONTIER, VoxelClass.NONE
K_SMALL = Intrinsics(160, 120, 150.0, 150.0, 79.5, 59.5)
EYE = np.array([0.0023, -0.4, 0.0031])
T_FRONT = Pose.look_at(EYE, EYE + np.array([0.0, 1.0, 0.0]))
BOX = ((-0.0317, 0.0042, -0.0317), (0.0283, 0.05, 0.0283))
WALL = ((-0.0857, 0.1043, -0.0857), (0.0783, 0.12, 0.0783))

Box = tuple[tuple[float, float, float], tuple[float, float, float]]
Sphere = tuple[tuple[float, float, float], float]


def render(T: Pose, k: Intrinsics, boxes: tuple[Box, ...] = (), spheres: tuple[Sphere, ...] = ()) -> DepthFrame:
    """Planar depth of axis-aligned boxes and spheres (0 = no return)."""
    v, u = np.meshgrid(np.arange(k.height), np.arange(k.width), indexing="ij")
    d = np.stack([(u - k.cx) / k.fx, (v - k.cy) / k.fy, np.ones(u.shape)], -1) @ T.rotation.T  # camera z = 1
    o = T.translation
    depth = np.full(u.shape, np.inf)
    for lo, hi in boxes:
        with np.errstate(divide="ignore", invalid="ignore"):
            t0, t1 = (np.array(lo) - o) / d, (np.array(hi) - o) / d
        t_near, t_far = np.nanmax(np.minimum(t0, t1), -1), np.nanmin(np.maximum(t0, t1), -1)
        depth = np.where((t_near <= t_far) & (t_near > 0), np.minimum(depth, t_near), depth)
    for c, r in spheres:
        oc = o - np.array(c)
        a, b, cc = (d * d).sum(-1), 2 * (d @ oc), oc @ oc - r * r
        disc = b * b - 4 * a * cc
        t = (-b - np.sqrt(np.maximum(disc, 0))) / (2 * a)
        depth = np.where((disc >= 0) & (t > 0), np.minimum(depth, t), depth)
    depth[~np.isfinite(depth)] = 0.0
    return DepthFrame(depth.astype(np.float32), T, k)


def at(m: VoxelMap, x: range | int, y: range | int, z: range | int) -> np.ndarray:
    """Classes of the voxels with lattice indices x, y, z (ints or ranges)."""
    lo = m.lower_index
    assert lo is not None
    sl = [slice(a.start - o, a.stop - o) if isinstance(a, range) else a - o for a, o in zip((x, y, z), lo, strict=True)]
    return m.classes[sl[0], sl[1], sl[2]]


def wall_map(integration: str = "projective", **kw: float) -> tuple[VoxelMap, DepthFrame]:
    m = VoxelMap(
        VoxelConfig(
            resolution=0.01, gamma=kw.pop("gamma", 0.0), integration=integration, floor=kw.pop("floor", False), **kw
        )
    )  # type: ignore[arg-type]
    frame = render(T_FRONT, K_SMALL, (BOX, WALL))
    m.integrate(frame, frame.points_world)
    return m, frame


# ---------------------------------------------------------------------------- classes of one frame


def test_before_first_frame_everything_is_empty() -> None:
    m = VoxelMap()
    assert m.bbox is None and m.shape == (0, 0, 0) and m.count(O) == 0
    assert m.centers(O).shape == (0, 3)
    assert m.snapshot().occupied.shape == (0, 3)


@pytest.mark.parametrize("integration", ["projective", "raycast"])
def test_box_in_front_of_wall(integration: str) -> None:
    m, _ = wall_map(integration)
    # between the box and the wall, beside the box's shadow: passed by every ray
    assert np.all(at(m, range(5, 7), range(0, 10), range(-7, 7)) == E)
    # the wall where it is not hidden by the box, and the box's front face
    assert np.all(at(m, range(4, 7), 10, range(-7, 7)) == O)
    assert np.all(at(m, range(-3, 2), 0, range(-3, 2)) == O)
    # behind the box's front face, and behind the wall
    assert np.all(at(m, range(-2, 1), range(1, 10), range(-2, 1)) == U)
    assert np.all(at(m, range(5, 7), range(11, 48), range(-6, 6)) == U)
    # unknown just behind the box's edge, next to its front face (occupied) and to free space beside it
    assert at(m, 2, 1, 0) == F
    assert at(m, 4, 1, 0) == E and at(m, 2, 0, 0) == O
    # every frontier voxel hugs the box's rim (y = 1) or a rim on the wall (its shadow's or its own)
    ys = np.argwhere(m.classes == F)[:, 1] + m.lower_index[1]  # type: ignore[index]
    assert set(np.unique(ys)) <= {1, 9, 10, 11}
    assert m.count(N) == 0  # the camera sees all of B


def test_first_bbox_doubles_the_diagonal_along_the_view_direction() -> None:
    m, _ = wall_map()
    # B0 = voxels of the points: lattice x, z in [-9, 8), y in [0, 11) -> extent (0.17, 0.11, 0.17)
    e = np.array([0.17, 0.11, 0.17])
    # sweep along +y: (0.11 + s)^2 + 2 * 0.17^2 = 4 |e|^2
    s = max(np.roots([1.0, 2 * 0.11, 0.11**2 + 2 * 0.17**2 - 4 * float(e @ e)]).real)
    assert np.linalg.norm(e + np.array([0.0, s, 0.0])) == pytest.approx(2 * np.linalg.norm(e))
    assert 0.47 < 0.11 + s <= 0.48  # snapped up to the lattice
    assert m.bbox is not None
    np.testing.assert_allclose(m.bbox.lower, [-0.09, 0.0, -0.09], atol=1e-12)
    np.testing.assert_allclose(m.bbox.upper, [0.08, 0.48, 0.08], atol=1e-12)
    assert m.shape == (17, 48, 17)
    np.testing.assert_allclose(m.origin, m.bbox.lower)


def test_bbox_covers_gamma_spheres_around_frontier() -> None:
    m0, _ = wall_map(gamma=0.0)
    m, _ = wall_map(gamma=0.02)
    assert m.bbox is not None and m0.bbox is not None
    f = m.centers(F)
    assert len(f) > 0
    assert np.all(m.bbox.contains(f - 0.02)) and np.all(m.bbox.contains(f + 0.02))
    assert np.all(m.bbox.lower <= m0.bbox.lower) and np.all(m.bbox.upper >= m0.bbox.upper)
    # frontier at the box's rim sits in lattice layer y = 1 (centre 0.015): 0.015 - 0.02 needs layer y = -1
    assert m.bbox.lower[1] == pytest.approx(-0.01) and m0.bbox.lower[1] == 0.0
    assert m.count(N) > 0  # added after the integration, never observed


def test_max_extent_caps_every_edge_centred_on_the_content() -> None:
    m, frame = wall_map(max_extent=0.1)
    assert m.bbox is not None
    # points span lattice x, z in [-9, 8) (centre -0.5 -> [-6, 4)) and y in [0, 11) (centre 5.5 -> [0, 10))
    np.testing.assert_allclose(m.bbox.lower, [-0.06, 0.0, -0.06], atol=1e-12)
    np.testing.assert_allclose(m.bbox.upper, [0.04, 0.1, 0.04], atol=1e-12)
    idx = m.voxel_of(frame.points_world)
    assert m.count(O) == len(np.unique(idx[np.all((idx >= 0) & (idx < 10), axis=1)], axis=0))
    stats = m.integrate(frame, frame.points_world)
    assert stats.n_points_outside == np.count_nonzero(np.any((idx < 0) | (idx >= 10), axis=1)) > 0
    assert not stats.bbox_grew


def test_stats_count_new_voxels() -> None:
    m = VoxelMap(VoxelConfig(gamma=0.0, floor=False))
    frame = render(T_FRONT, K_SMALL, (BOX, WALL))
    stats = m.integrate(frame, frame.points_world)
    assert stats.bbox_grew and stats.seconds > 0
    assert stats.n_new_occupied == m.count(O) > 0
    assert stats.n_new_empty == m.count(E) > 0
    assert stats.n_new_unknown == m.count(U) + m.count(F)
    assert stats.n_frontier == m.count(F) > 0
    again = m.integrate(frame, frame.points_world)
    assert (again.n_new_occupied, again.n_new_empty, again.n_new_unknown, again.bbox_grew) == (0, 0, 0, False)


# ---------------------------------------------------------------------------- several frames


def test_empty_and_occupied_are_final() -> None:
    m, _ = wall_map()
    before = m.classes.copy()
    assert at(m, -1, 5, -1) == U and at(m, -1, 10, -1) == U  # behind the box; the wall in its shadow
    # the box is gone: its shadow is seen free, the wall behind it is seen
    frame2 = render(T_FRONT, K_SMALL, (WALL,))
    m.integrate(frame2, frame2.points_world)
    assert np.all(at(m, range(-3, 2), 0, range(-3, 2)) == O)  # seen as free now, but occupied is final
    assert at(m, -1, 5, -1) == E and at(m, -1, 10, -1) == O  # unknown may still change
    # a new box in front of the wall lands in empty voxels: they stay empty, also behind it
    box2 = ((0.0457, 0.0313, -0.0317), (0.0683, 0.06, 0.0283))
    frame3 = render(T_FRONT, K_SMALL, (box2, WALL))
    stats = m.integrate(frame3, frame3.points_world)
    assert np.all(at(m, range(5, 7), range(0, 10), range(-7, 7)) == E)
    assert stats.n_new_occupied == 0
    final = (before == E) | (before == O)
    np.testing.assert_array_equal(m.classes[final], before[final])


def test_growth_keeps_classes_at_their_world_positions() -> None:
    m, _ = wall_map()
    old, old_origin = m.classes.copy(), m.origin
    box3 = ((-0.1483, 0.0513, -0.0217), (-0.1217, 0.08, 0.0183))  # outside B on the -x side
    frame2 = render(T_FRONT, K_SMALL, (BOX, WALL, box3))
    stats = m.integrate(frame2, frame2.points_world)
    assert stats.bbox_grew
    np.testing.assert_allclose(m.origin, [-0.15, 0.0, -0.09], atol=1e-12)  # the grid shifted by 6 voxels
    o = np.rint((old_origin - m.origin) / 0.01).astype(int)
    np.testing.assert_array_equal(o, [6, 0, 0])
    sub = m.classes[o[0] : o[0] + old.shape[0], o[1] : o[1] + old.shape[1], o[2] : o[2] + old.shape[2]]
    # rays into the old B are unchanged by the new box: the only changes are unknown <-> frontier on the old
    # -x face, whose new neighbours beside the wall were seen free
    changed = sub != old
    assert np.all(np.isin(old[changed], [U, F])) and np.all(np.isin(sub[changed], [U, F]))
    assert changed.sum() > 0 and np.all(np.argwhere(changed)[:, 0] == 0)
    assert np.all(at(m, range(-14, -12), 5, range(-2, 1)) == O)  # the new box's front face


# ---------------------------------------------------------------------------- bad input, rollback


def test_empty_first_frame_is_rejected_and_map_unchanged() -> None:
    m = VoxelMap()
    frame = render(T_FRONT, K_SMALL, (WALL,))
    with pytest.raises(ValueError, match="empty frame"):
        m.integrate(frame, np.zeros((0, 3)))
    assert m.bbox is None and m.shape == (0, 0, 0)
    # later frames may bring no points: the depth still carves
    m.integrate(frame, frame.points_world)
    stats = m.integrate(render(T_FRONT, K_SMALL), np.zeros((0, 3)))
    assert stats.n_new_occupied == 0 and stats.n_new_empty > 0  # the wall is gone: behind it is free


def test_bad_points_and_frame_are_rejected() -> None:
    m, frame = wall_map()
    before = m.classes.copy()
    pts = frame.points_world.copy()
    pts[3, 1] = np.nan
    with pytest.raises(ValueError, match="points_world"):
        m.integrate(frame, pts)
    with pytest.raises(ValueError, match="points_world"):
        m.integrate(frame, pts[:, :2])
    with pytest.raises(ValueError, match="frame"):
        m.integrate("frame", frame.points_world)  # type: ignore[arg-type]
    np.testing.assert_array_equal(m.classes, before)


def test_failure_mid_integration_leaves_map_unchanged(monkeypatch: pytest.MonkeyPatch) -> None:
    m, _ = wall_map()
    before, bbox = m.classes.copy(), m.bbox
    box3 = ((-0.1483, 0.0513, -0.0217), (-0.1217, 0.08, 0.0183))  # would grow B
    frame2 = render(T_FRONT, K_SMALL, (WALL, box3))

    def boom(classes: np.ndarray) -> np.ndarray:
        raise RuntimeError("boom")

    monkeypatch.setattr(vm, "relabel_frontier", boom)
    with pytest.raises(RuntimeError, match="boom"):
        m.integrate(frame2, frame2.points_world)
    np.testing.assert_array_equal(m.classes, before)
    assert m.bbox is not None and bbox is not None
    np.testing.assert_array_equal(m.bbox.lower, bbox.lower)


def test_classes_view_is_read_only_and_copy_is_deep() -> None:
    m, _ = wall_map()
    with pytest.raises(ValueError):
        m.classes[0, 0, 0] = O
    c = m.copy()
    m.integrate(render(T_FRONT, K_SMALL), np.zeros((0, 3)))
    assert c.count(U) != m.count(U)
    assert c.count(U) == wall_map()[0].count(U)


def test_snapshot_and_centers() -> None:
    m, _ = wall_map()
    snap = m.snapshot()
    assert snap.resolution == 0.01
    assert len(snap.occupied) == m.count(O) and len(snap.frontier) == m.count(F)
    assert len(snap.unknown) == m.count(U) and len(snap.empty) == m.count(E)
    # lattice voxel (2, 0, 0) (on the box's front face) has centre (0.025, 0.005, 0.005)
    assert np.any(np.all(np.isclose(snap.occupied, [0.025, 0.005, 0.005]), axis=1))
    np.testing.assert_array_equal(m.voxel_of(snap.occupied), np.argwhere(m.classes == O))


# ---------------------------------------------------------------------------- projective vs raycast


def _near_depth_edge(frame: DepthFrame, centers: np.ndarray, res: float) -> np.ndarray:
    """(N,) bool: a depth discontinuity lies within the projected footprint (+1 px) of each voxel centre (N, 3)."""
    d = frame.depth.astype(np.float64)
    jump = np.zeros(d.shape, bool)
    for a in (0, 1):
        dd = np.abs(np.diff(d, axis=a)) > 3 * res  # also catches return / no return
        jump[tuple(slice(0, -1) if i == a else slice(None) for i in (0, 1))] |= dd
        jump[tuple(slice(1, None) if i == a else slice(None) for i in (0, 1))] |= dd
    dist = ndimage.distance_transform_edt(~jump)
    k = frame.intrinsics
    p = frame.T_world_camera.inverse().apply(centers)
    u = np.clip(np.rint(k.fx * p[:, 0] / p[:, 2] + k.cx).astype(int), 0, k.width - 1)
    v = np.clip(np.rint(k.fy * p[:, 1] / p[:, 2] + k.cy).astype(int), 0, k.height - 1)
    footprint = k.fx * np.sqrt(3) / 2 * res / p[:, 2]  # pixels: radius of the voxel's bounding sphere
    return np.asarray(dist)[v, u] <= footprint + 1.0


def _compare(frame: DepthFrame, res: float, check_map: bool = True) -> tuple[float, int, VoxelMap]:
    """Agreement of the two observation models on the map's grid; asserts where they may differ."""
    m = VoxelMap(VoxelConfig(resolution=res, gamma=0.0, floor=False))
    m.integrate(frame, frame.points_world)
    proj = observe_projective(frame, m.origin, res, m.shape)
    empty_seen, unknown_seen = ray_observations(*pixel_rays(frame), m.origin, res, m.shape)
    ray = np.where(unknown_seen, U, np.where(empty_seen, E, 0))  # what observe_raycast returns
    touched = (proj > 0) | (ray > 0)
    differ = touched & (proj != ray)
    # Allowed: the 9 samples of 'projective' (centre, corners rounded to pixels) and the pixel rays of
    # 'raycast' see a voxel differently only where part of it is hidden: at occlusion edges (silhouettes), and
    # where the surface clips a corner of the voxel (a sliver between pixel rays); plus voxels at the frustum's
    # border whose centre projects outside the image (only the raycast touches them).
    border = (ray > 0) & (proj == 0)
    assert not np.any((proj > 0) & (ray == 0))
    idx = np.argwhere(differ & ~border)
    centers = m.origin + (idx + 0.5) * res
    pixel = frame.points_camera[:, 2].max() / frame.intrinsics.fx  # largest pixel spacing on the surface
    touches_surface = KDTree(frame.points_world).query(centers)[0] < np.sqrt(3) / 2 * res + pixel
    assert np.all(_near_depth_edge(frame, centers, res) | touches_surface)
    # where 'projective' carves and 'raycast' does not, some pixel ray did pass the whole voxel
    assert np.all(empty_seen[(proj == E) & (ray == U)])
    if check_map:  # occupied comes from the points: identical in both modes
        m_ray = VoxelMap(VoxelConfig(resolution=res, gamma=0.0, integration="raycast", floor=False))
        m_ray.integrate(frame, frame.points_world)
        np.testing.assert_array_equal(m.classes == O, m_ray.classes == O)
    return float(np.count_nonzero(touched & ~differ) / np.count_nonzero(touched)), int(touched.sum()), m


@pytest.mark.parametrize(
    ("name", "boxes", "spheres", "min_agree"),
    [
        ("sphere", (), (((0.003, 0.002, 0.1), 0.1),), 0.97),
        ("box+wall", (BOX, WALL), (), 0.99),
        ("two spheres", (), (((0.05, 0.0, 0.08), 0.06), ((-0.06, 0.03, 0.1), 0.05)), 0.97),
    ],
)
def test_projective_agrees_with_raycast(name: str, boxes: tuple, spheres: tuple, min_agree: float) -> None:
    T = Pose.look_at([0.43, 0.12, 0.25], [0.003, 0.002, 0.1]) if spheres else T_FRONT
    agree, touched, _ = _compare(render(T, K_SMALL, boxes, spheres), 0.01)
    assert touched > 10_000
    assert agree >= min_agree, f"{name}: {agree:.4f}"


def test_fine_grid_agrees() -> None:
    """0.005 m voxels, about 80^3 of them; agreement improves (a smaller share of voxels straddles an edge).

    The speed of projective integration is measured in benchmarks/bench_voxel_map.py."""
    k = Intrinsics(320, 240, 300.0, 300.0, 159.5, 119.5)
    frame = render(Pose.look_at([0.5, 0.14, 0.3], [0.003, 0.002, 0.125]), k, spheres=(((0.003, 0.002, 0.125), 0.125),))
    agree, _, m = _compare(frame, 0.005, check_map=False)
    assert m.classes.size >= 80**3
    assert agree >= 0.985


def test_floor_keeps_bounding_box_above_the_plate() -> None:
    """Departure from the paper (documented at VoxelConfig.floor): B stops at the plate top."""
    eye = np.array([0.3, 0.0, 0.45])  # looking down at a box standing on the plate (z = 0)
    T = Pose.look_at(eye, [0.0, 0.0, 0.03])
    lifted: Box = ((-0.05, -0.05, 0.0), (0.05, 0.05, 0.06))
    frame = render(T, K_SMALL, (lifted,))
    points = frame.points_world[frame.points_world[:, 2] > 0.002]
    free = VoxelMap(VoxelConfig(gamma=0.02, floor=False))
    free.integrate(frame, points)
    floored = VoxelMap(VoxelConfig(gamma=0.02))
    floored.integrate(frame, points)
    assert free.bbox is not None and floored.bbox is not None
    assert free.bbox.lower[2] < -0.02  # the paper's growth along the view direction goes under the plate
    assert floored.bbox.lower[2] == pytest.approx(0.0)
    assert np.all(floored.centers(VoxelClass.FRONTIER)[:, 2] > 0.0)
    assert np.array_equal(floored.bbox.upper, free.bbox.upper)
