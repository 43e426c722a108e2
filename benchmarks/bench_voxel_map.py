"""Timings of the voxel map: projective vs Amanatides–Woo raycast integration, and their agreement.

Run: ``.venv/bin/python benchmarks/bench_voxel_map.py [--repeat 5]``

1. Observation alone on fixed cubic grids (a 0.4 m cube: 40^3 voxels at 0.01 m, 80^3 at 0.005 m)
   with a 640 x 480 depth image of a sphere (radius 0.12 m) seen from 0.5 m.
2. ``VoxelMap.integrate`` over four views around the sphere (B grows), both modes, both resolutions,
   and the agreement of the resulting maps. Timings are wall time, best of ``--repeat`` for the
   projective model (single runs for the raycast); a loaded machine inflates them.
"""

from __future__ import annotations

import argparse
import time

import numpy as np

from planner.config import VoxelConfig
from planner.raycast import observe_raycast
from planner.types import DepthFrame, Intrinsics, Pose, VoxelClass
from planner.voxel_map import VoxelMap, observe_projective

CENTER = np.array([0.003, 0.002, 0.12])
RADIUS = 0.12


def render_sphere(T: Pose, k: Intrinsics) -> DepthFrame:
    """Planar depth of the sphere (0 = no return)."""
    v, u = np.meshgrid(np.arange(k.height), np.arange(k.width), indexing="ij")
    d = np.stack([(u - k.cx) / k.fx, (v - k.cy) / k.fy, np.ones(u.shape)], -1) @ T.rotation.T
    oc = T.translation - CENTER
    a, b, c = (d * d).sum(-1), 2 * (d @ oc), oc @ oc - RADIUS**2
    disc = b * b - 4 * a * c
    t = (-b - np.sqrt(np.maximum(disc, 0))) / (2 * a)
    depth = np.where((disc >= 0) & (t > 0), t, 0.0)
    return DepthFrame(depth.astype(np.float32), T, k)


def view(azimuth_deg: float, elevation_deg: float = 30.0, distance: float = 0.5) -> Pose:
    az, el = np.radians(azimuth_deg), np.radians(elevation_deg)
    eye = CENTER + distance * np.array([np.cos(el) * np.cos(az), np.cos(el) * np.sin(az), np.sin(el)])
    return Pose.look_at(eye, CENTER)


def best_of(fn, repeat: int) -> float:  # type: ignore[no-untyped-def]
    times = []
    for _ in range(repeat):
        t0 = time.perf_counter()
        fn()
        times.append(time.perf_counter() - t0)
    return min(times)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--repeat", type=int, default=5, help="best of this many runs for the projective timings")
    args = ap.parse_args()
    k = Intrinsics()
    frame = render_sphere(view(20.0), k)
    print(f"depth image {k.width}x{k.height}, {np.count_nonzero(frame.depth)} returns")

    print("\n1. observation on a fixed 0.4 m cube around the sphere")
    for res in (0.01, 0.005):
        n = round(0.4 / res)
        lower = CENTER - 0.2
        lower = np.floor(lower / res) * res
        proj = best_of(lambda: observe_projective(frame, lower, res, (n, n, n)), args.repeat)  # noqa: B023
        t0 = time.perf_counter()
        ray_obs = observe_raycast(frame, lower, res, (n, n, n))
        ray = time.perf_counter() - t0
        p_obs = observe_projective(frame, lower, res, (n, n, n))
        touched = (p_obs > 0) | (ray_obs > 0)
        agree = np.count_nonzero(touched & (p_obs == ray_obs)) / np.count_nonzero(touched)
        print(
            f"  res {res:.3f} grid {n}^3 ({n**3} voxels): projective {proj * 1e3:7.2f} ms   "
            f"raycast {ray * 1e3:8.1f} ms   agreement {agree:.4f} of {touched.sum()} touched voxels"
        )

    print("\n2. VoxelMap.integrate over 4 views (azimuth 20, 110, 200, 290 deg, elevation 30 deg)")
    frames = [render_sphere(view(az), k) for az in (20.0, 110.0, 200.0, 290.0)]
    for res in (0.01, 0.005):
        maps = {}
        for mode in ("projective", "raycast"):
            m = VoxelMap(VoxelConfig(resolution=res, integration=mode))
            secs = []
            for f in frames:  # best of --repeat integrations of this frame into copies of the map
                runs = args.repeat if mode == "projective" else 1
                secs.append(min(m.copy().integrate(f, f.points_world).seconds for _ in range(runs)))
                m.integrate(f, f.points_world)
            maps[mode] = m
            counts = ", ".join(f"{c.name.lower()} {m.count(c)}" for c in VoxelClass if c != VoxelClass.NONE)
            print(
                f"  res {res:.3f} {mode:10s} grid {m.shape}: per frame "
                + " ".join(f"{s * 1e3:7.1f}" for s in secs)
                + f" ms   ({counts})"
            )
        a, b = maps["projective"], maps["raycast"]
        if a.shape == b.shape and np.array_equal(a.origin, b.origin):
            ca, cb = a.classes, b.classes
            touched = (ca > 0) | (cb > 0)
            agree = np.count_nonzero(touched & (ca == cb)) / np.count_nonzero(touched)
            occ = np.array_equal(ca == VoxelClass.OCCUPIED, cb == VoxelClass.OCCUPIED)
            print(f"    final maps agree on {agree:.4f} of touched voxels; occupied identical: {occ}")
        else:
            print(f"    final B differs: {a.shape} vs {b.shape} (frontier-driven growth differs)")


if __name__ == "__main__":
    main()
