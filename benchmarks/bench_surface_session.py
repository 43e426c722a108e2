"""The surface layer in a live session: the per-view update time in the session's worker, bytes per update.

Run: ``nice .venv/bin/python benchmarks/bench_surface_session.py [--model ../shared/models/bunny.obj]
[--views 10] [--seed 0]``

A real :class:`workbench.SessionRegistry` (worker processes on, the default planner config, the simulated UR5
cell) scans the mesh (0.2 m, y-up) for ``--views`` views: capture, then plan + approve of the best view. After
each view the session's worker fused the registered frame and extracted the surface and its layer
(``workbench/surface/live.py``). Printed per view:

- ``update s``: the worker's surface update (integrate + extract + simplify; ``SurfaceUpdate.seconds``, measured
  in the worker; scoring against the ground truth is left out), goal <= 0.3 s on the bunny; ``cpu s``: its CPU
  time (``SurfaceUpdate.cpu_seconds``, every thread of the worker), which the machine's load does not inflate;
- ``approve s``: the whole approve (move, render, integrate the map and the surface, journal) for context;
- ``layer kB``: what the page's ``/surface`` node sends to one tab: float32 vertices + uint32 faces of the
  simplified layer (the buffers viser ships; its zstd framing only shrinks them), goal <= 300 kB;
- ``to server kB``: the pickled ``SurfaceUpdate`` the worker sends back (full mesh + layer);
- the surface's F@5mm against the mesh (the per-view metric of ``GET /api/sessions/{id}/metrics``).

Wall times on a shared machine are inflated by its load: the script also prints the machine's load average.
"""

from __future__ import annotations

import argparse
import os
import pickle
import shutil
import statistics
import sys
import tempfile
import time
from pathlib import Path

from workbench import SessionRegistry, WorkbenchSettings


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=(__doc__ or "").splitlines()[0])
    parser.add_argument("--model", type=Path, default=Path("../shared/models/bunny.obj"))
    parser.add_argument("--views", type=int, default=10)
    parser.add_argument("--seed", type=int, default=0)
    args = parser.parse_args(argv)
    if not args.model.is_file():
        print(f"--model: no such file {args.model}", file=sys.stderr)
        return 2
    with tempfile.TemporaryDirectory() as tmp:
        models = Path(tmp) / "models"
        models.mkdir()
        shutil.copyfile(args.model, models / args.model.name)  # a copy in a temporary folder (a link is not listed)
        registry = SessionRegistry(WorkbenchSettings(models_dir=models, data_dir=Path(tmp) / "data"))
        try:
            session = registry.create(args.model.name, seed=args.seed)
            rows = []
            for view in range(1, args.views + 1):
                t0 = time.perf_counter()
                if view == 1:
                    session.capture()
                else:
                    plan = session.plan()
                    if plan.plan.best_index is None:
                        print(f"view {view}: no reachable view left")
                        break
                    t0 = time.perf_counter()
                    session.approve(plan.plan_id, plan.plan.best_index)
                approve = time.perf_counter() - t0
                update = session.surface
                assert update is not None
                rows.append(
                    (
                        view,
                        update.seconds,
                        approve,
                        update.layer_bytes / 1000,
                        len(pickle.dumps(update)) / 1000,
                        0 if update.mesh is None else update.mesh.triangles,
                        0 if update.layer is None else update.layer.triangles,
                        update.fscore_5mm,
                        update.error,
                        update.cpu_seconds,
                        os.getloadavg()[0],
                    )
                )
                r = rows[-1]
                f = "-" if r[7] is None else f"{r[7]:.4f}"
                print(
                    f"view {r[0]:2d}  update {r[1]:.3f} s (cpu {r[9]:.3f} s, load {r[10]:.1f})  approve {r[2]:.2f} s  "
                    f"layer {r[3]:.0f} kB  "
                    f"to server {r[4]:.0f} kB  triangles {r[5]} (layer {r[6]})  F@5mm {f}"
                    + ("" if r[8] is None else f"  error: {r[8]}"),
                    flush=True,
                )
        finally:
            registry.close()
    if rows:
        updates, cpu = [r[1] for r in rows], [r[9] for r in rows]
        print(
            f"\n{args.model.stem}, {len(rows)} views: update median {statistics.median(updates):.3f} s, "
            f"max {max(updates):.3f} s (goal <= 0.3 s); cpu median {statistics.median(cpu):.3f} s, "
            f"max {max(cpu):.3f} s; layer max {max(r[3] for r in rows):.0f} kB (goal <= 300 kB); "
            f"load average {os.getloadavg()[0]:.1f} on {os.cpu_count()} cores"
        )
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
