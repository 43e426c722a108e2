"""Time ``score_views``: 400 candidates x 20 / 50 / 100 ellipsoids (analytic), and the raster reference.

Run: ``.venv/bin/python benchmarks/bench_score.py``. The scene is random ellipsoids inside a 0.2 m box
(plus a few large ones that fill or leave the image), seen from the default candidate hemisphere.
"""

from __future__ import annotations

import argparse
import time

import numpy as np

from planner.candidates import propose_candidates
from planner.config import CandidateConfig, PartitionConfig, ScoringConfig
from planner.projection import project, raster_pixels
from planner.scoring import score_views
from planner.types import BoundingBox, Ellipsoid, Intrinsics


def random_ellipsoids(n: int, rng: np.random.Generator) -> list[Ellipsoid]:
    out = []
    for i in range(n):
        q, _ = np.linalg.qr(rng.normal(size=(3, 3)))
        q *= np.sign(np.linalg.det(q))
        big = i % 10 == 0  # some fill or leave the image
        axes = rng.uniform(0.08, 0.25, 3) if big else rng.uniform(0.005, 0.04, 3)
        center = rng.uniform([-0.1, -0.1, 0.0], [0.1, 0.1, 0.2])
        out.append(Ellipsoid(center, axes, q, "frontier" if i % 2 else "occupied"))
    return out


def best_of(fn, repeats: int) -> float:
    times = []
    for _ in range(repeats):
        t0 = time.perf_counter()
        fn()
        times.append(time.perf_counter() - t0)
    return min(times)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__)
    parser.add_argument("--repeats", type=int, default=7)
    args = parser.parse_args()
    rng = np.random.default_rng(0)
    K = Intrinsics()
    bbox = BoundingBox(np.array([-0.1, -0.1, 0.0]), np.array([0.1, 0.1, 0.2]))
    cands, _, _ = propose_candidates(bbox, CandidateConfig(), PartitionConfig())
    mask = np.ones(len(cands), dtype=bool)
    cfg = ScoringConfig()
    print(f"score_views, {len(cands)} candidates, {K.width}x{K.height}, analytic area (best of {args.repeats}):")
    for n in (20, 50, 100):
        ells = random_ellipsoids(n, rng)
        score_views(ells, cands, K, cfg, mask)  # warm up
        t = best_of(lambda ells=ells: score_views(ells, cands, K, cfg, mask), args.repeats)
        status = np.bincount(project(ells, [c.T_world_camera for c in cands], K).status.ravel(), minlength=4)
        print(
            f"  {n:4d} ellipsoids: {1e3 * t:7.2f} ms  ({1e6 * t / (n * len(cands)):.2f} us/pair; "
            f"front/behind/straddle/inside pairs {status.tolist()})"
        )
    ells = random_ellipsoids(10, rng)
    pairs = [(e, c.T_world_camera) for e in ells[:5] for c in cands[::100]]
    t = best_of(lambda: [raster_pixels(e, p, K) for e, p in pairs], 3)
    print(f"raster_pixels reference: {len(pairs)} pairs in {1e3 * t:.1f} ms ({1e3 * t / len(pairs):.2f} ms/pair)")


if __name__ == "__main__":
    main()
