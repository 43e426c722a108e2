"""Time the simulated depth camera: one 640 x 480 render (open3d RaycastingScene), mug and Stanford bunny.

Run: ``.venv/bin/python benchmarks/bench_render.py [--repeat 20] [--models ../shared/models]``.
Prints the median and the maximum wall time per render (the first render, which builds the scene,
is left out).
"""

from __future__ import annotations

import argparse
import statistics
import time
from pathlib import Path

from devices.builtins import make_builtin
from devices.mesh import load_mesh
from devices.sim import SimulatedCamera
from planner.types import Pose


def time_renders(camera: SimulatedCamera, repeat: int) -> list[float]:
    pose = Pose.look_at((-0.45, 0.0, 0.35), (0.0, 0.0, 0.08))
    camera.render(pose)
    times = []
    for _ in range(repeat):
        t0 = time.perf_counter()
        camera.render(pose)
        times.append(time.perf_counter() - t0)
    return times


def main() -> int:
    p = argparse.ArgumentParser(description=(__doc__ or "").splitlines()[0])
    p.add_argument("--repeat", type=int, default=20)
    p.add_argument("--models", type=Path, default=Path("../shared/models"))
    args = p.parse_args()
    meshes = {"mug (built-in)": make_builtin("mug")}
    bunny = args.models / "bunny.obj"
    if bunny.exists():
        meshes["bunny"] = load_mesh(bunny, up="y", size=0.2)
    print(f"{'object':<16}{'faces':>9}{'median ms':>11}{'max ms':>9}")
    for name, mesh in meshes.items():
        times = time_renders(SimulatedCamera(mesh), args.repeat)
        print(f"{name:<16}{len(mesh.faces):>9}{1000 * statistics.median(times):>11.1f}{1000 * max(times):>9.1f}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
