"""The sensor ceiling: how much of each development mesh a sensor can deliver from any candidate view at all.

Run: ``nice .venv/bin/python benchmarks/bench_sensor_ceiling.py [--models all] [--sensors ideal,realsense-d435,...]
[--min-elevation 10]``.

For each mesh (placed as the bench places it, 10,000 surface samples, seed 0) and sensor, the 400 candidates of a B
3 cm around the mesh (the sensor's range rule, ``planner.candidates``; no reachability, no view budget) are tried
on every sample: a sample is *deliverable* when some candidate has it in the image (the sensor's rendered
intrinsics), in line of sight, within range (planar depth), within the grazing limit and, for a triangulating
sensor, in line of sight of the second viewpoint too. Printed per sensor: the shares of samples by the best check
they passed (delivered, second-viewpoint shadow, grazing, range, outside every image, occluded) and the recall@5mm
of the deliverable samples (share of samples within 5 mm of one): what no planner on this candidate set can
exceed. ``--min-elevation``: the candidates' lowest parallel, degrees (10, the paper's cell; the cell gives a sensor
with a grazing limit -5, ``devices.planner_noise.LOW_ELEVATION_DEG``). docs/experiments/sensors.md, "Why do the D405 and
structured light lose recall?" and "The sphere about the object and the low parallels".
"""

from __future__ import annotations

import argparse
import math
import statistics
from collections.abc import Sequence
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np
from bench_sensors import development_meshes
from numpy.typing import NDArray
from scipy.spatial import KDTree

from planner.types import Pose

if TYPE_CHECKING:
    from devices.sim import SimulatedCamera

CHECKS = ("delivered", "shadow", "grazing", "range", "outside", "occluded")


def best_check(
    camera: SimulatedCamera, samples: NDArray[np.float64], normals: NDArray[np.float64], poses: Sequence[Pose]
) -> NDArray[np.int64]:
    """(N,) index into CHECKS: the best any pose of ``poses`` did for each sample (0 = delivered)."""
    from devices.sensors import second_view_visible

    sensor, k = camera.sensor, camera.intrinsics
    best = np.full(len(samples), len(CHECKS) - 1)
    cos_limit = math.cos(math.radians(sensor.max_incidence_deg))
    for T in poses:
        p = (samples - T.translation) @ T.rotation  # camera frame
        z = p[:, 2]
        zs = np.maximum(z, 1e-9)
        u, v = k.fx * p[:, 0] / zs + k.cx, k.fy * p[:, 1] / zs + k.cy
        code = np.full(len(samples), 5)
        sight = second_view_visible(camera._scene, T.translation, samples) & (z > 0)
        code[sight] = 4
        ok = sight & (u >= 0) & (u <= k.width - 1) & (v >= 0) & (v <= k.height - 1)
        ranged = (z >= sensor.min_range) & (z <= min(sensor.max_range, camera.config.max_depth))
        code[ok & ~ranged] = 3
        ok &= ranged
        ray = (samples - T.translation) / np.linalg.norm(samples - T.translation, axis=1)[:, None]
        grazing = np.abs(np.einsum("ij,ij->i", ray, normals)) < cos_limit
        code[ok & grazing] = 2
        ok &= ~grazing
        if sensor.baseline > 0:
            second = second_view_visible(camera._scene, T.translation + sensor.baseline * T.rotation[:, 0], samples)
            code[ok & ~second] = 1
            ok &= second
        code[ok] = 0
        best = np.minimum(best, code)
    return best


def main() -> None:
    import open3d as o3d

    from devices.builtins import resolve_model
    from devices.config import CameraConfig
    from devices.mesh import sample_surface
    from devices.sensors import sensor_named
    from devices.sim import SimulatedCamera
    from planner.candidates import propose_candidates
    from planner.config import CandidateConfig, PartitionConfig
    from planner.types import BoundingBox

    p = argparse.ArgumentParser(description=(__doc__ or "").split("\n", 1)[0])
    p.add_argument("--models", default="all")
    p.add_argument("--sensors", default="ideal,realsense-d435,realsense-d405,structured-light")
    p.add_argument("--min-elevation", type=float, default=CandidateConfig().min_elevation_deg)
    args = p.parse_args()
    models = development_meshes() if args.models == "all" else [Path(m) for m in args.models.split(",") if m]
    names = [s for s in args.sensors.split(",") if s]
    recall: dict[str, list[float]] = {n: [] for n in names}
    for path in models:
        _, mesh = resolve_model(str(path), up="y", size=0.2)
        samples = sample_surface(mesh, 10_000, seed=0)
        scene = o3d.t.geometry.RaycastingScene()
        vertices = np.ascontiguousarray(mesh.vertices, np.float32)  # from_numpy shares memory: keep them alive
        triangles = np.ascontiguousarray(mesh.faces, np.uint32)
        scene.add_triangles(o3d.core.Tensor.from_numpy(vertices), o3d.core.Tensor.from_numpy(triangles))
        query = o3d.core.Tensor.from_numpy(np.ascontiguousarray(samples, np.float32))
        faces = scene.compute_closest_points(query)["primitive_ids"].numpy()
        normals = np.asarray(mesh.face_normals)[faces]
        lo, hi = mesh.bounds
        for name in names:
            camera = SimulatedCamera(mesh, CameraConfig(sensor=name))
            max_range = sensor_named(name).max_range
            config = CandidateConfig(
                max_range=max_range if math.isfinite(max_range) else 0.0, min_elevation_deg=args.min_elevation
            )
            candidates, _, radius = propose_candidates(BoundingBox(lo - 0.03, hi + 0.03), config, PartitionConfig())
            best = best_check(camera, samples, normals, [c.T_world_camera for c in candidates])
            delivered = samples[best == 0]
            gaps = np.asarray(KDTree(delivered).query(samples)[0]) if len(delivered) else np.full(len(samples), np.inf)
            rec = float(np.mean(gaps <= 0.005))
            recall[name].append(rec)
            shares = " ".join(f"{c} {np.mean(best == i):.3f}" for i, c in enumerate(CHECKS))
            print(f"{path.stem:18} {name:18} R {radius:.3f}  {shares}  recall@5mm ceiling {rec:.4f}", flush=True)
    for name in names:
        print(
            f"mean of {len(models)}: {name:18} recall@5mm ceiling {statistics.fmean(recall[name]):.4f} "
            f"(lowest parallel {args.min_elevation:g} deg)",
            flush=True,
        )


if __name__ == "__main__":
    main()
