"""Ray-casting baselines: gain formulas on hand-made rays, traversal, candidate rays, evaluators."""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
import pytest

from planner.baselines import gains
from planner.baselines.evaluators import (
    AporaEvaluator,
    OcclusionAwareEvaluator,
    RandomEvaluator,
    RearSideEntropyEvaluator,
    UnobservedVoxelEvaluator,
    raycast_view_gains,
)
from planner.baselines.rays import clip_to_box, traverse_rays, view_rays
from planner.config import PlannerConfig
from planner.evaluators import EvaluationContext, evaluator_names, make_evaluator
from planner.partitions import select_best
from planner.planner import Planner
from planner.raycast import traverse
from planner.types import BoundingBox, Candidate, DepthFrame, Intrinsics, Pose
from planner.types import VoxelClass as V

E, O, U, F, N = V.EMPTY, V.OCCUPIED, V.UNKNOWN, V.FRONTIER, V.NONE
PAD = gains.PAD


def h(p: float) -> float:
    """Binary entropy in bits, written out."""
    return -(p * math.log2(p) + (1 - p) * math.log2(1 - p))


# --------------------------------------------------------------------------- gains on hand-made rays


def test_class_probabilities_and_entropies() -> None:
    seq = np.array([N, E, O, U, F, PAD], dtype=np.uint8)
    assert gains.occupancy_probability(seq).tolist() == [0.5, 0.12, 0.97, 0.5, 0.5, 0.0]
    assert h(0.12) == pytest.approx(0.5293608652873644)
    np.testing.assert_allclose(gains.ENTROPY_LUT[seq], [1.0, h(0.12), h(0.97), 1.0, 1.0, 0.0])
    with pytest.raises(ValueError, match="classes"):
        gains.occlusion_aware_gain([E, 7])


def test_occlusion_aware_gain_by_hand() -> None:
    # visibility: 1, (1 - .12), (1 - .12)^2, (1 - .12)^2 (1 - .5)
    expected = 1 * h(0.12) + 0.88 * h(0.12) + 0.88**2 * 1.0 + 0.88**2 * 0.5 * h(0.97)
    assert gains.occlusion_aware_gain([E, E, U, O]) == pytest.approx(expected, rel=1e-12)
    assert gains.occlusion_aware_gain([E, E, U, O]) == pytest.approx(1.8448669540926312, rel=1e-12)


def test_unobserved_voxel_gain_uses_one_minus_occupancy() -> None:
    # unobserved voxels U, F, N at visibilities .88^2, .88^2 * .5, .88^2 * .25
    assert gains.unobserved_voxel_gain([E, E, U, F, N]) == pytest.approx(0.7744 * 1.75, rel=1e-12)
    buggy = 0.12**2 * (1 + 0.5 + 0.25)  # the public implementations' p_vis *= p_occ
    assert gains.unobserved_voxel_gain([E, E, U, F, N]) != pytest.approx(buggy)


@pytest.mark.parametrize(
    ("ray", "expected"),
    [
        ([E, U, U, O], 0.88 * 1 + 0.88 * 0.5 * 1),  # unobserved run behind the surface, then the surface
        ([U, E, U, O], 0.5 * 0.88 * 1),  # the run is broken by an empty voxel: only the last U
        ([E, U, F, N, O], 0.88 + 0.44 + 0.22),  # frontier and none count as unobserved
        ([E, U, U], 0.0),  # leaves B without hitting anything
        ([E, E, O], 0.0),  # front side of a surface: no unobserved voxel before it
    ],
)
def test_rear_side_entropy_by_hand(ray: list[int], expected: float) -> None:
    assert gains.rear_side_entropy_gain(ray) == pytest.approx(expected, rel=1e-12)


def test_rear_side_mask_marks_the_run_before_the_hit() -> None:
    assert gains.rear_side_mask([U, E, U, U, O, PAD]).tolist() == [False, False, True, True, False, False]


def test_apora_gain_by_hand() -> None:
    # observed voxels (E, O) get p_obj 0 whatever is passed; unknown: .2 then .5 behind (1 - .2)
    ray, p_obj = [E, U, F, O], [0.9, 0.2, 0.5, 0.7]
    assert gains.apora_gain(ray, p_obj) == pytest.approx(0.2 * 1 * 1 + 0.5 * 0.8 * 1, rel=1e-12)
    with pytest.raises(ValueError, match="p_obj"):
        gains.apora_gain(ray, [0.1, 0.2])


def test_padding_changes_no_gain() -> None:
    rays = [[E, U, U, O], [U, E, U, O], [E, O], [U, U, U, U, E, U]]
    padded = np.full((len(rays), 8), PAD, dtype=np.uint8)
    p_obj = np.zeros(padded.shape)
    for i, r in enumerate(rays):
        padded[i, : len(r)] = r
        p_obj[i, : len(r)] = np.linspace(0.1, 0.6, len(r))
    for fn in (gains.occlusion_aware_gain, gains.unobserved_voxel_gain, gains.rear_side_entropy_gain):
        np.testing.assert_allclose(fn(padded), [fn(r) for r in rays], rtol=1e-12)
    single = [gains.apora_gain(r, p_obj[i, : len(r)]) for i, r in enumerate(rays)]
    np.testing.assert_allclose(gains.apora_gain(padded, p_obj), single, rtol=1e-12)


def test_streaming_accumulators_match_closed_form() -> None:
    rng = np.random.default_rng(3)
    classes = rng.choice(np.array([N, E, O, U, F], dtype=np.uint8), size=(300, 25))
    classes[rng.random(classes.shape) < 0.1] = PAD  # PAD mid-sequence too: it must act as a no-op voxel
    classes[:, -3:] = PAD
    p_obj = rng.random(classes.shape)
    pairs = [
        (gains.OcclusionAwareAccumulator, gains.occlusion_aware_gain(classes)),
        (gains.UnobservedVoxelAccumulator, gains.unobserved_voxel_gain(classes)),
        (gains.RearSideEntropyAccumulator, gains.rear_side_entropy_gain(classes)),
        (gains.AporaAccumulator, gains.apora_gain(classes, p_obj)),
    ]
    for cls, expected in pairs:
        acc = cls(len(classes))
        rows = np.arange(len(classes))
        for k in range(classes.shape[1]):
            acc.add(rows, classes[:, k], p_obj[:, k])
        np.testing.assert_allclose(acc.gain, expected, rtol=1e-12, atol=1e-15)


def test_object_probability_units() -> None:
    # six frontier voxels at 1..6 voxel edges from x: alpha |x - e| = 0.1 * (distance in voxels)
    for res in (0.01, 0.004):
        frontier = np.array([[k * res, 0.0, 0.0] for k in range(1, 7)])
        p = gains.object_probability(np.zeros((1, 3)), frontier, res)
        assert p[0] == pytest.approx(math.exp(-0.01 * (1 + 4 + 9 + 16 + 25 + 36)), rel=1e-12)
    seven = np.vstack([np.array([[k * 0.01, 0.0, 0.0] for k in range(1, 7)]), [[0.5, 0.0, 0.0]]])
    assert gains.object_probability(np.zeros((1, 3)), seven, 0.01)[0] == pytest.approx(math.exp(-0.91))
    assert gains.object_probability(np.zeros((1, 3)), [[0.02, 0, 0]], 0.01)[0] == pytest.approx(math.exp(-0.04))
    assert gains.object_probability(np.zeros((2, 3)), np.zeros((0, 3)), 0.01).tolist() == [0.0, 0.0]


def test_object_probability_grid_only_on_unobserved_voxels() -> None:
    classes = np.full((4, 3, 3), E, dtype=np.uint8)
    classes[2:] = U
    classes[2, 1, 1] = F
    classes[0, 0, 0] = O
    p = gains.object_probability_grid(classes, [0.1, 0.2, 0.3], 0.01)
    assert np.all(p[classes == E] == 0) and p[0, 0, 0] == 0
    assert p[2, 1, 1] == 1.0  # a lone frontier voxel is its own nearest frontier voxel
    assert p[3, 1, 1] == pytest.approx(math.exp(-0.01))
    assert gains.object_probability_grid(np.full((2, 2, 2), U, np.uint8), [0, 0, 0], 0.01).max() == 0.0


# --------------------------------------------------------------------------- traversal


LO = np.array([-0.1, 0.05, -0.13])
RES = 0.02
SHAPE = (13, 17, 11)
HI = LO + np.array(SHAPE) * RES


def random_rays(n: int, seed: int) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    rng = np.random.default_rng(seed)
    origins = rng.uniform(LO - 0.2, HI + 0.2, (n, 3))
    origins[: n // 4] = rng.uniform(LO, HI, (n // 4, 3))  # some start inside the grid
    dirs = rng.normal(size=(n, 3))
    dirs /= np.linalg.norm(dirs, axis=1, keepdims=True)
    t0, t1 = clip_to_box(origins, dirs, LO, HI)
    hit = t1 > t0
    return origins[hit], dirs[hit], t0[hit], t1[hit]


def reference_linear(origin: np.ndarray, direction: np.ndarray) -> np.ndarray:
    idx = traverse(origin, direction, np.inf, LO, RES, SHAPE)
    return np.ravel_multi_index(idx.T, SHAPE)


def test_traversal_agrees_with_reference_traverse() -> None:
    origins, dirs, t0, t1 = random_rays(1500, seed=0)
    assert len(origins) > 400
    lin = traverse_rays(origins, dirs, t0, t1, LO, RES, SHAPE)
    for r in range(len(origins)):
        n = int(np.count_nonzero(lin[r] >= 0))
        np.testing.assert_array_equal(lin[r, :n], reference_linear(origins[r], dirs[r]))
        assert np.all(lin[r, n:] == -1)  # padding only at the end


def test_rays_stop_at_first_occupied_voxel() -> None:
    rng = np.random.default_rng(1)
    occupied = rng.random(SHAPE) < 0.04
    origins, dirs, t0, t1 = random_rays(1500, seed=2)
    lin = traverse_rays(origins, dirs, t0, t1, LO, RES, SHAPE, stop=occupied)
    n_hit = 0
    for r in range(len(origins)):
        ref = reference_linear(origins[r], dirs[r])
        hits = np.flatnonzero(occupied.reshape(-1)[ref])
        expected = ref if len(hits) == 0 else ref[: hits[0] + 1]
        np.testing.assert_array_equal(lin[r][lin[r] >= 0], expected)
        n_hit += len(hits) > 0
    assert n_hit > 100  # both kinds of rays were exercised


def test_rays_cover_the_projected_box() -> None:
    intr = Intrinsics()
    res = 0.01
    lo, hi = np.array([-0.1, -0.08, 0.0]), np.array([0.1, 0.08, 0.12])
    centre = 0.5 * (lo + hi)
    pose = Pose.look_at(centre + np.array([0.0, 0.0, 0.5]), centre, up=(0.0, 1.0, 0.0))  # looking straight down
    rays = view_rays([pose], intr, lo, hi, res)
    stride = intr.fx * res / 0.5
    # pixel pattern: spacing at most one voxel at B's centre depth, spanning B's projection
    us, vs = np.unique(rays.pixels[:, 0]), np.unique(rays.pixels[:, 1])
    assert np.diff(us).max() <= math.ceil(stride) and np.diff(vs).max() <= math.ceil(stride)
    top_depth = 0.5 - 0.06
    half_u, half_v = intr.fx * 0.1 / top_depth, intr.fy * 0.08 / top_depth  # the near face is the widest
    assert us.min() - intr.cx <= -half_u + stride and us.max() - intr.cx >= half_u - stride
    assert vs.min() - intr.cy <= -half_v + stride and vs.max() - intr.cy >= half_v - stride
    assert rays.counts.tolist() == [len(rays)] and len(rays) == pytest.approx(len(us) * len(vs), rel=0.01)
    # every voxel of the face the camera looks at is entered by some ray
    shape = tuple(np.round((hi - lo) / res).astype(int))
    lin = traverse_rays(rays.origins, rays.directions, rays.t_enter, rays.t_exit, lo, res, shape)
    first = np.unravel_index(lin[:, 0], shape)
    top = set(zip(first[0][first[2] == shape[2] - 1], first[1][first[2] == shape[2] - 1], strict=True))
    assert len(top) == shape[0] * shape[1]
    np.testing.assert_allclose(np.linalg.norm(rays.directions, axis=1), 1.0)


def test_camera_inside_box_uses_the_whole_image() -> None:
    intr = Intrinsics(width=40, height=30, fx=30.0, fy=30.0, cx=19.5, cy=14.5)
    pose = Pose.look_at([0.0, 0.0, 0.0], [1.0, 0.0, 0.0])
    rays = view_rays([pose], intr, [-0.1, -0.1, -0.1], [0.1, 0.1, 0.1], 0.01)
    assert len(rays) == 40 * 30 and np.all(rays.t_enter == 0)


# --------------------------------------------------------------------------- evaluators


@dataclass
class FakeMap:
    """The part of ``VoxelMap`` the evaluators read."""

    classes: np.ndarray
    origin: np.ndarray
    resolution: float

    @property
    def bbox(self) -> BoundingBox:
        return BoundingBox(self.origin, self.origin + np.array(self.classes.shape) * self.resolution)


def wall_map() -> FakeMap:
    """A 20^3 box of 1 cm voxels: empty for x < 10, an occupied wall at x = 10, unknown behind it (+x),
    the layer touching the wall frontier."""
    c = np.full((20, 20, 20), E, dtype=np.uint8)
    c[10] = O
    c[11:] = U
    c[11] = F
    return FakeMap(c, np.array([-0.1, -0.1, 0.0]), 0.01)


def candidates(vm: FakeMap, eyes: list[list[float]]) -> tuple[Candidate, ...]:
    centre = vm.bbox.center
    return tuple(Candidate(i, Pose.look_at(np.array(e) + centre, centre), 0.0, 0.0, 0, 0) for i, e in enumerate(eyes))


def context(vm: FakeMap, cands: tuple[Candidate, ...], eligible: list[bool], seed: int = 0) -> EvaluationContext:
    return EvaluationContext(vm, cands, Intrinsics(), np.array(eligible), np.random.default_rng(seed))  # type: ignore[arg-type]


def test_registry_lists_the_baselines() -> None:
    names = evaluator_names()
    for name in ("raycast-apora", "raycast-oa", "raycast-uv", "raycast-rse", "random"):
        assert name in names
        assert make_evaluator(name, PlannerConfig()).name == name


@pytest.fixture(scope="module")
def pocket_rays() -> tuple[FakeMap, list[Pose], list[tuple[int, np.ndarray, np.ndarray]]]:
    """A wall map with an unknown pocket in front of the wall, three views, and every ray's voxel sequence
    by the reference ``planner.raycast.traverse``, cut after the first occupied voxel: (view, classes, p_obj)."""
    vm = wall_map()
    vm.classes[6:10, 4:12, 2:9] = U  # every gain is non-trivial from -x too
    poses = [c.T_world_camera for c in candidates(vm, [[0.4, 0.05, 0.1], [-0.4, -0.1, 0.2], [0.05, 0.4, 0.25]])]
    rays = view_rays(poses, Intrinsics(), vm.bbox.lower, vm.bbox.upper, 0.01)
    p_obj = gains.object_probability_grid(vm.classes, vm.origin, 0.01)
    seqs = []
    for r in range(len(rays)):
        idx = traverse(rays.origins[r], rays.directions[r], np.inf, vm.origin, 0.01, vm.classes.shape)
        cls = vm.classes[tuple(idx.T)]
        hits = np.flatnonzero(cls == O)
        cut = len(cls) if len(hits) == 0 else hits[0] + 1
        seqs.append((int(rays.owner[r]), cls[:cut], p_obj[tuple(idx[:cut].T)]))
    return vm, poses, seqs


@pytest.mark.parametrize("kind", ["apora", "oa", "uv", "rse"])
def test_view_gain_is_the_sum_of_reference_ray_gains(kind: str, pocket_rays) -> None:
    vm, poses, seqs = pocket_rays
    got = raycast_view_gains(vm.classes, vm.origin, 0.01, vm.bbox.lower, vm.bbox.upper, poses, Intrinsics(), kind)  # type: ignore[arg-type]
    fn = {
        "apora": gains.apora_gain,
        "oa": lambda s, p: gains.occlusion_aware_gain(s),
        "uv": lambda s, p: gains.unobserved_voxel_gain(s),
        "rse": lambda s, p: gains.rear_side_entropy_gain(s),
    }[kind]
    expected = np.zeros(len(poses))
    for view, seq, p in seqs:
        expected[view] += fn(seq, p)
    assert np.all(expected > 0)
    np.testing.assert_allclose(got, expected, rtol=1e-9)


@pytest.mark.parametrize(
    "cls", [AporaEvaluator, OcclusionAwareEvaluator, UnobservedVoxelEvaluator, RearSideEntropyEvaluator]
)
def test_raycast_evaluators_on_a_wall(cls: type) -> None:
    vm = wall_map()
    cands = candidates(vm, [[-0.45, 0.0, 0.1], [0.45, 0.0, 0.1], [0.0, -0.45, 0.1]])
    ev = cls(PlannerConfig())
    result = ev.evaluate(context(vm, cands, [True, True, False]))
    s = result.scores
    assert [x.index for x in s] == [0, 1, 2] and [x.eligible for x in s] == [True, True, False]
    if cls is OcclusionAwareEvaluator:
        # OA also counts the entropy left in EMPTY voxels (H(0.12) = 0.53 bit) and UNKNOWN voxels are
        # half-opaque (P_o = 0.5): ten empty voxels before the wall outweigh the unknown side
        assert s[0].score > s[1].score > 0
        return
    assert s[1].score > s[0].score and s[1].score > 0
    assert select_best(s) == 1
    for x in s:
        assert x.frontier == x.score and x.occupied == 0.0
        assert x.ranks.shape == x.weights.shape == x.pixels.shape == x.weighted.shape == (0,)
    assert result.ellipsoids == () and set(result.timings) == {"score"} and result.timings["score"] > 0
    assert ev.last_breakdown["n_rays"] > 1500
    if cls is RearSideEntropyEvaluator:
        assert s[0].score == 0.0  # from the empty side the wall is seen from the front: no rear side


def test_random_evaluator_is_uniform_over_eligible_candidates() -> None:
    vm = wall_map()
    cands = candidates(vm, [[0.4 * math.cos(a), 0.4 * math.sin(a), 0.1] for a in np.linspace(0, 6, 6)])
    eligible = [True, False, True, True, False, True]
    ev = make_evaluator("random", PlannerConfig())
    assert isinstance(ev, RandomEvaluator)
    rng = np.random.default_rng(5)
    picks = [
        select_best(ev.evaluate(context(vm, cands, eligible, seed)).scores) for seed in rng.integers(0, 2**32, 2000)
    ]
    counts = np.bincount(np.array(picks), minlength=6)
    assert counts[1] == counts[4] == 0
    assert np.all(np.abs(counts[[0, 2, 3, 5]] - 500) < 90)  # ~4 sigma of a binomial(2000, 1/4)
    a = ev.evaluate(context(vm, cands, eligible, seed=11)).scores
    b = ev.evaluate(context(vm, cands, eligible, seed=11)).scores
    assert [x.score for x in a] == [x.score for x in b]
    assert all(x.occupied == 0 and x.frontier == x.score for x in a)


def sphere_frame() -> DepthFrame:
    """A depth frame of a 5 cm sphere on the plate, seen from the side."""
    rng = np.random.default_rng(0)
    d = rng.normal(size=(60000, 3))
    points = 0.05 * d / np.linalg.norm(d, axis=1, keepdims=True) + np.array([0.0, 0.0, 0.06])
    pose = Pose.look_at([0.35, 0.05, 0.2], [0.0, 0.0, 0.06])
    return DepthFrame.from_points(points, pose, Intrinsics())


@pytest.mark.parametrize("name", ["raycast-apora", "raycast-oa", "raycast-uv", "raycast-rse", "random"])
def test_planner_plans_with_each_baseline(name: str) -> None:
    config = PlannerConfig().replace(candidates={"count": 24, "parallels": 3})
    planner = Planner(config, evaluator=name)
    planner.integrate(sphere_frame())
    plan = planner.plan()
    assert len(plan.scores) == len(plan.candidates) == 24
    assert plan.best_index is not None and plan.scores[plan.best_index].eligible
    assert plan.ellipsoids == () and plan.timings["score"] > 0
    eligible = [s.score for s in plan.scores if s.eligible]
    assert plan.scores[plan.best_index].score == max(eligible)
    if name != "random":
        assert max(eligible) > 0
