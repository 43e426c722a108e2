"""Benchmark of the ellipsoid fit (paper §III-D): BIC search speed and fidelity, MVEE speed and tightness.

For voxel-centre sets made from trimesh surfaces (0.01 m lattice) and a frontier-like shell piece:

- exhaustive: scikit-learn GaussianMixture for every T in [t_min, t_max] (the reference, ``bic_sweep``);
- fast cold: ``EllipsoidFitter.fit`` with no previous state;
- fast warm: the fitter first fits the set minus a cap of ~9 % of its voxels (the previous iteration),
  then the full set (10 % more voxels, as after one more view) - only the second fit is timed;
- gap: (BIC of the chosen model - best exhaustive BIC) / n, must be <= 0.05;
- MVEE: ``mvee`` on 500 points of an ellipsoid surface, and the fitter's ellipsoids against converged
  MVEEs of every voxel's 8 corners (volume ratio).

Times are medians of several runs (the machine may be shared: look at min too).
- ``--sequence``: warm-started chains like a scan (a growing surface, a moving frontier band), each
  step checked against its own exhaustive sweep.

Run: ``.venv/bin/python benchmarks/bench_fit.py [--quick] [--sets union-S,torus] [--sequence]``.
"""

from __future__ import annotations

import argparse
import time
from collections.abc import Callable

import numpy as np
import trimesh
from numpy.typing import NDArray

from planner.clustering import bic_gap, bic_sweep
from planner.config import ClusterConfig
from planner.ellipsoids import EllipsoidFitter
from planner.mvee import mvee

RES = 0.01


def voxelize(points: NDArray[np.float64], res: float = RES) -> NDArray[np.float64]:
    """Unique voxel centres (M, 3) of points (N, 3) on a lattice of edge ``res``."""
    return np.unique(np.round(points / res).astype(np.int64), axis=0).astype(np.float64) * res


def union_surface(scale: float, samples: int = 300_000, seed: int = 0) -> NDArray[np.float64]:
    """Surface voxels of a box + cylinder + sphere union (parts inside another primitive removed)."""
    box_c, box_h = np.array([0.0, 0.0, 0.04]) * scale, np.array([0.06, 0.04, 0.04]) * scale
    cyl_c, cyl_r, cyl_h = np.array([0.0, 0.0, 0.11]) * scale, 0.03 * scale, 0.04 * scale
    sph_c, sph_r = np.array([0.07, 0.0, 0.07]) * scale, 0.045 * scale
    meshes = [
        trimesh.creation.box(extents=2 * box_h).apply_translation(box_c),
        trimesh.creation.cylinder(radius=cyl_r, height=2 * cyl_h, sections=64).apply_translation(cyl_c),
        trimesh.creation.icosphere(subdivisions=4, radius=sph_r).apply_translation(sph_c),
    ]
    total = sum(m.area for m in meshes)
    p = np.vstack(
        [
            trimesh.sample.sample_surface(m, int(samples * m.area / total), seed=seed + i)[0]
            for i, m in enumerate(meshes)
        ]
    )
    eps = 1e-9
    inside = (
        np.all(np.abs(p - box_c) < box_h - eps, axis=1)
        | ((np.sum((p - cyl_c)[:, :2] ** 2, axis=1) < (cyl_r - eps) ** 2) & (np.abs(p[:, 2] - cyl_c[2]) < cyl_h - eps))
        | (np.linalg.norm(p - sph_c, axis=1) < sph_r - eps)
    )
    return voxelize(p[~inside])


def torus(major: float = 0.15, minor: float = 0.05, samples: int = 400_000) -> NDArray[np.float64]:
    mesh = trimesh.creation.torus(major, minor, major_sections=96, minor_sections=48)
    return voxelize(trimesh.sample.sample_surface(mesh, samples, seed=0)[0])


def shell_piece(radius: float, theta_max: float = 1.0) -> NDArray[np.float64]:
    """Frontier-like: one voxel thick spherical cap (polar angle < theta_max) of a sphere of ``radius``."""
    r = radius / RES
    g = np.arange(-int(r) - 2, int(r) + 3)
    P = np.stack(np.meshgrid(g, g, g, indexing="ij"), axis=-1).reshape(-1, 3).astype(float)
    d = np.linalg.norm(P, axis=1)
    polar = np.arccos(np.clip(P[:, 2] / np.maximum(d, 1e-9), -1.0, 1.0))
    return P[(np.abs(d - r) <= 0.5) & (polar < theta_max)] * RES + np.array([0.0, 0.0, 0.05])


def previous_iteration(points: NDArray[np.float64], fraction: float = 1 / 11) -> NDArray[np.float64]:
    """The set minus the cap of ``fraction`` of its voxels farthest along a fixed direction."""
    proj = points @ np.array([0.6, 0.48, 0.64])
    return points[proj < np.quantile(proj, 1.0 - fraction)]


SETS: dict[str, Callable[[], NDArray[np.float64]]] = {
    "union-S": lambda: union_surface(1.0),
    "union-M": lambda: union_surface(2.0),
    "union-L": lambda: union_surface(3.5),
    "torus": torus,
    "shell-M": lambda: shell_piece(0.2),
    "shell-L": lambda: shell_piece(0.3),
}


def median_time(fn: Callable[[], object], repeats: int) -> tuple[float, float]:
    times = []
    for _ in range(repeats):
        t0 = time.perf_counter()
        fn()
        times.append(time.perf_counter() - t0)
    return float(np.median(times)), float(np.min(times))


def bench_set(name: str, points: NDArray[np.float64], config: ClusterConfig, repeats: int) -> dict[str, float]:
    n = len(points)
    t0 = time.perf_counter()
    sweep = bic_sweep(points, range(config.t_min, config.t_max + 1), config, RES)
    t_sweep = time.perf_counter() - t0

    cold = EllipsoidFitter(config, RES, "occupied")
    cold_fit = cold.fit(points)[1]
    cold_timings = []
    for _ in range(repeats):
        cold.reset()
        cold.fit(points)
        cold_timings.append(cold.last_timings)

    prev = previous_iteration(points)
    warm = EllipsoidFitter(config, RES, "occupied")
    warm_timings = []
    warm_fit = cold_fit
    for _ in range(repeats):
        warm.reset()
        warm.fit(prev)
        warm_fit = warm.fit(points)[1]
        warm_timings.append(warm.last_timings)

    def stats(timings: list[dict[str, float]], key: str | None) -> float:
        vals = [sum(t.values()) if key is None else t[key] for t in timings]
        return float(np.median(vals))

    best_t = min(sweep, key=lambda t: sweep[t])
    row = {
        "n": n,
        "sweep_s": t_sweep,
        "best_t": best_t,
        "cold_t": cold_fit.t_chosen,
        "cold_s": stats(cold_timings, None),
        "cold_gap": bic_gap(dict(cold_fit.bic)[cold_fit.t_chosen], sweep, n),
        "warm_t": warm_fit.t_chosen,
        "warm_s": stats(warm_timings, None),
        "warm_min_s": float(min(sum(t.values()) for t in warm_timings)),
        "warm_cluster_s": stats(warm_timings, "cluster"),
        "warm_ellipsoids_s": stats(warm_timings, "ellipsoids"),
        "warm_gap": bic_gap(dict(warm_fit.bic)[warm_fit.t_chosen], sweep, n),
        "warm_evals": len(warm_fit.bic),
    }
    print(
        f"{name:8s} n={n:5d} | sweep {t_sweep:6.1f}s T*={best_t:2d} | cold {row['cold_s'] * 1e3:6.1f}ms "
        f"T={row['cold_t']:2d} gap={row['cold_gap']:+.4f} | warm {row['warm_s'] * 1e3:6.1f}ms "
        f"(min {row['warm_min_s'] * 1e3:5.1f}; cluster {row['warm_cluster_s'] * 1e3:5.1f} + ellipsoids "
        f"{row['warm_ellipsoids_s'] * 1e3:5.1f}) T={row['warm_t']:2d} gap={row['warm_gap']:+.4f} "
        f"evals={row['warm_evals']}",
        flush=True,
    )
    return row


def bench_mvee(repeats: int) -> None:
    rng = np.random.default_rng(0)
    v = rng.normal(size=(500, 3))
    v /= np.linalg.norm(v, axis=1, keepdims=True)
    pts = v * np.array([0.05, 0.03, 0.01]) + np.array([0.1, 0.0, 0.2])
    med, best = median_time(lambda: mvee(pts, tol=1e-4), repeats)
    print(f"mvee(500 surface points, tol 1e-4): median {med * 1e3:.2f} ms (min {best * 1e3:.2f} ms)")


def bench_tightness(points: NDArray[np.float64], config: ClusterConfig) -> None:
    """Fitter ellipsoids vs converged MVEEs of all corners of each cluster's voxels (volume ratio)."""
    from planner import clustering
    from planner.ellipsoids import _CORNERS

    fitter = EllipsoidFitter(config, RES, "occupied")
    ellipsoids, _ = fitter.fit(points)
    assert fitter.mixture is not None
    x = points / RES
    labels = clustering.assign(x, fitter.mixture)
    ratios = []
    for e, k in zip(ellipsoids, np.unique(labels), strict=True):
        corners = (x[labels == k][:, None, :] + _CORNERS[None]).reshape(-1, 3) * RES
        _, A = mvee(corners, tol=1e-6, max_iter=100_000)
        ratios.append(e.volume / (4.0 / 3.0 * np.pi / np.sqrt(np.linalg.det(A))))
    r = np.array(ratios)
    print(f"ellipsoid volume / converged MVEE: median {np.median(r):.4f} max {r.max():.4f} ({len(r)} clusters)")


def band(lo: float, hi: float, radius: float = 0.2) -> NDArray[np.float64]:
    """Frontier-like band of a sphere shell: polar angle in [lo, hi) (moves as the scan proceeds)."""
    r = radius / RES
    g = np.arange(-int(r) - 2, int(r) + 3)
    P = np.stack(np.meshgrid(g, g, g, indexing="ij"), axis=-1).reshape(-1, 3).astype(float)
    d = np.linalg.norm(P, axis=1)
    polar = np.arccos(np.clip(P[:, 2] / np.maximum(d, 1e-9), -1.0, 1.0))
    return P[(np.abs(d - r) <= 0.5) & (polar >= lo) & (polar < hi)] * RES


def bench_sequence(config: ClusterConfig) -> None:
    """Warm-started chains like a scan: a growing surface (occupied) and a moving band (frontier)."""
    full = union_surface(3.0)
    proj = full @ np.array([0.6, 0.48, 0.64])
    chains = {
        "occupied (union grows 40% -> 100%)": [full[proj <= np.quantile(proj, q)] for q in (0.4, 0.55, 0.7, 0.85, 1.0)],
        "frontier (band moves 0.15 rad/step)": [band(0.3 + 0.15 * k, 0.9 + 0.15 * k) for k in range(5)],
    }
    for name, chain in chains.items():
        fitter = EllipsoidFitter(config, RES, "frontier")
        cells = []
        for points in chain:
            fit = fitter.fit(points)[1]
            sweep = bic_sweep(points, range(config.t_min, config.t_max + 1), config, RES)
            gap = bic_gap(dict(fit.bic)[fit.t_chosen], sweep, len(points))
            best_t = min(sweep, key=lambda t: sweep[t])
            cells.append(f"n={len(points)} T={fit.t_chosen}/{best_t} {fit.seconds * 1e3:.0f}ms gap={gap:+.3f}")
        print(f"{name}: " + " | ".join(cells), flush=True)


def main() -> None:
    parser = argparse.ArgumentParser(description=(__doc__ or "").splitlines()[0])
    parser.add_argument("--sets", default=",".join(SETS), help="comma-separated names: " + ", ".join(SETS))
    parser.add_argument("--quick", action="store_true", help="union-S, union-M and shell-M only, 3 repeats")
    parser.add_argument("--repeats", type=int, default=7)
    parser.add_argument("--sequence", action="store_true", help="also warm-started scan-like chains (slow: sweeps)")
    args = parser.parse_args()
    names = ["union-S", "union-M", "shell-M"] if args.quick else args.sets.split(",")
    repeats = 3 if args.quick else args.repeats
    config = ClusterConfig()
    rows = {}
    for name in names:
        rows[name] = bench_set(name, SETS[name](), config, repeats)
    gaps = [max(r["cold_gap"], r["warm_gap"]) for r in rows.values()]
    print(
        f"worst gap per voxel {max(gaps):+.4f} (limit 0.05); warm median over sets "
        f"{np.median([r['warm_s'] for r in rows.values()]) * 1e3:.1f} ms; sweep total "
        f"{sum(r['sweep_s'] for r in rows.values()):.1f}s"
    )
    bench_mvee(repeats * 3)
    bench_tightness(SETS[names[-1]](), config)
    if args.sequence:
        bench_sequence(config)


if __name__ == "__main__":
    main()
