"""What one live session costs the server process: its RSS before and after a create, a capture, a plan and an
approve at a given voxel grid (and the peak RSS of its worker process), to derive and check the per-session voxel
budget (``server.max_session_voxels``, workbench/sources/limits.py).

    .venv/bin/python benchmarks/bench_session_memory.py [--resolution 0.002] [--max-extent 0.3] [--views 2]
        [--initial-diagonal-factor 10]
"""

from __future__ import annotations

import argparse
import gc
import sys
import tempfile
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from devices.config import CameraConfig, DeviceConfig
from workbench import SessionRegistry, WorkbenchSettings


def rss_mb(pid: int | str = "self") -> float:
    """Resident set size of a process, MB (from /proc)."""
    for line in Path(f"/proc/{pid}/status").read_text().splitlines():
        if line.startswith("VmRSS:"):
            return int(line.split()[1]) / 1024
    return 0.0


def hwm_mb(pid: int) -> float:
    """Peak resident set size of a process, MB (from /proc)."""
    for line in Path(f"/proc/{pid}/status").read_text().splitlines():
        if line.startswith("VmHWM:"):
            return int(line.split()[1]) / 1024
    return 0.0


def main() -> None:
    parser = argparse.ArgumentParser(description="what one live session costs the server process")
    parser.add_argument("--resolution", type=float, default=0.002)
    parser.add_argument("--max-extent", type=float, default=0.3)
    parser.add_argument("--views", type=int, default=2, help="views after the first capture (plan + approve each)")
    parser.add_argument("--model", default="mug")
    parser.add_argument(
        "--initial-diagonal-factor", type=float, default=2.0, help="10: the box starts at max_extent (the worst case)"
    )
    args = parser.parse_args()
    root = Path(tempfile.mkdtemp(prefix="nbv-memory-"))
    camera = CameraConfig(width=320, height=240, fx=300.0, fy=300.0, cx=160.0, cy=120.0)
    settings = WorkbenchSettings(
        models_dir=root / "models", data_dir=root / "data", devices=DeviceConfig(camera=camera), max_session_voxels=0
    )
    registry = SessionRegistry(settings)
    config = {
        "voxel": {
            "resolution": args.resolution,
            "max_extent": args.max_extent,
            "initial_diagonal_factor": args.initial_diagonal_factor,
        },
        "candidates": {"count": 60},
        "cluster": {"t_min": 2, "t_max": 6},
    }
    gc.collect()
    before = rss_mb()
    t0 = time.monotonic()
    session = registry.create(args.model, config=config)
    session.capture()
    for _ in range(args.views):
        pending = session.plan()
        session.approve(pending.plan_id, index=pending.plan.best_index)
    session.plan()
    gc.collect()
    after = rss_mb()
    shape = session.planner.voxel_map.classes.shape
    voxels = int(shape[0] * shape[1] * shape[2])
    worker = session.worker.pid if session.worker is not None else None
    peak = hwm_mb(worker) if worker is not None else 0.0
    print(
        f"resolution {args.resolution} max_extent {args.max_extent}: grid {shape} = {voxels / 1e6:.2f} M voxels; "
        f"server RSS {before:.0f} -> {after:.0f} MB (+{after - before:.0f} MB, "
        f"{(after - before) * 1024 * 1024 / max(voxels, 1):.0f} B/voxel); worker peak {peak:.0f} MB; "
        f"{time.monotonic() - t0:.1f} s"
    )
    registry.close()


if __name__ == "__main__":
    main()
