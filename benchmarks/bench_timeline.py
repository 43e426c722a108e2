"""Looking back at a scan: timeline step -> drawn in a tab's viewer, and the recording's size and build time.

Run: ``PYTHONPATH=. nice .venv/bin/python benchmarks/bench_timeline.py [--views 10] [--models ../shared/models]
[--sensor realsense-d435 --calibration typical]``.

A real workbench app (viser on, the session's worker), one raw viser client bound by a viewer ticket
(tests/viewer_wire.py), the Stanford bunny at resolution 0.01 m with the paper's other defaults (400 candidates):
capture, then plan + approve of the planner's choice up to ``--views`` views and a plan pending after the last.
Then ``PUT /api/scene/{viewer}/timeline`` steps the viewer over every view and back to now:

- first look: the journal replayed in the session's worker (every view integrated and planned again) and drawn;
- step -> drawn: a cached step, from the request until the viewer got the step's last frame (medians [max] over
  every step forward, then back, then to now);
- recording: ``GET /api/sessions/{id}/recording`` (the steps cached): its zip size (budget 10 MB for 10 bunny
  views), the scene's share, the request's time; and the recording of the journal alone (``nbv record``'s path:
  the journal replayed here in a replay cell, then drawn and serialised).

Goal: timeline step -> drawn <= 0.5 s on the bunny.
"""

from __future__ import annotations

import argparse
import statistics
import sys
import tempfile
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from fastapi.testclient import TestClient

from app.main import create_app
from app.scene.recording import build_recording
from app.settings import AppSettings
from tests.viewer_wire import RawViewer
from workbench.journal import journal_timeline

QUIET = 0.4
"""Seconds without a new frame after which a step counts as drawn."""


def drawn_at(raw: RawViewer, since: int, timeout: float = 120.0) -> float:
    """When the last frame after the first ``since`` of ``raw`` arrived, once none came for QUIET s."""
    deadline = time.perf_counter() + timeout
    while time.perf_counter() < deadline:
        new = raw.frames[since:]
        if new and time.perf_counter() - new[-1][0] > QUIET:
            return new[-1][0]
        time.sleep(0.02)
    raise TimeoutError("the viewer received nothing")


def fmt(values: list[float]) -> str:
    return f"{statistics.median(values):6.3f} s [{max(values):6.3f}]" if values else "–"


def main() -> int:
    p = argparse.ArgumentParser(description=(__doc__ or "").splitlines()[0])
    p.add_argument("--views", type=int, default=10)
    p.add_argument("--models", type=Path, default=Path("../shared/models"))
    p.add_argument("--model", default="bunny", help="a model name (its file in --models) or a built-in")
    p.add_argument("--sensor", default=None, help="a simulated sensor (GET /api/sensors), default: the ideal one")
    p.add_argument("--calibration", default=None, help="a calibration preset (GET /api/sensors)")
    args = p.parse_args()
    with tempfile.TemporaryDirectory() as tmp:
        settings = AppSettings(viser_port=0, scene=True, models_dir=args.models, data_dir=Path(tmp))
        with TestClient(create_app(settings), base_url="http://127.0.0.1") as client:
            names = [m["name"] for m in client.get("/api/models").json()]
            model = next((n for n in names if n.startswith(args.model)), args.model)
            camera = (
                {"sensor": args.sensor, "calibration": args.calibration} if args.sensor or args.calibration else None
            )
            body = {"model": model, "config": {"voxel": {"resolution": 0.01}}, "camera": camera}
            r = client.post("/api/sessions", json=body)
            assert r.status_code == 201, r.text
            sid = r.json()["id"]
            v = client.post("/api/viewer", json={"session": sid}).json()
            port = v["port"]
            raw = RawViewer(
                f"ws://127.0.0.1:{port}/?ticket={v['url'].split('ticket%3D')[1]}", f"http://127.0.0.1:{port}"
            )
            try:
                drawn_at(raw, 0)
                t_scan = time.perf_counter()
                client.post(f"/api/sessions/{sid}/capture").raise_for_status()
                for view in range(1, args.views + 1):
                    plan = client.post(f"/api/sessions/{sid}/plan").json()
                    if view < args.views and plan["best"] is not None:
                        body = {"plan_id": plan["plan_id"], "index": plan["best"]["index"]}
                        client.post(f"/api/sessions/{sid}/approve", json=body).raise_for_status()
                t_scan = time.perf_counter() - t_scan
                views = client.get(f"/api/sessions/{sid}").json()["iteration"]
                drawn_at(raw, 0)
                viewer = v["viewer"]

                def show(view: int | None) -> float:
                    mark = raw.mark()
                    t0 = time.perf_counter()
                    r = client.put(f"/api/scene/{viewer}/timeline", json={"view": view})
                    assert r.status_code == 200, r.text
                    return drawn_at(raw, mark) - t0

                first = show(1)
                forward = [show(j) for j in range(2, views + 1)]
                back = [show(j) for j in range(views - 1, 0, -1)]
                now = show(None)
                t0 = time.perf_counter()
                rec = client.get(f"/api/sessions/{sid}/recording")
                t_rec = time.perf_counter() - t0
                assert rec.status_code == 200, rec.text
                directory = Path(tmp) / "sessions" / sid
                t0 = time.perf_counter()
                steps, scene = journal_timeline(directory)
                t_replay = time.perf_counter() - t0
                built = build_recording(steps, scene, f"NBV scan {sid}")
            finally:
                raw.close()
    sensor = f"{args.sensor or 'ideal'} sensor, {args.calibration or 'no'} calibration error"
    print(f"{model}, {views} views at 0.01 m, 400 candidates ({sensor}); the scan took {t_scan:.1f} s")
    print(f"  first look (journal replayed in the worker + drawn)  {first:6.2f} s")
    print(f"  timeline step -> drawn, forward                       {fmt(forward)}")
    print(f"  timeline step -> drawn, back                          {fmt(back)}")
    print(f"  timeline -> now drawn                                 {now:6.3f} s")
    print(f"  all cached steps                                      {fmt(forward + back + [now])}   (goal <= 0.5 s)")
    print(f"  recording (GET, steps cached)   {len(rec.content) / 1e6:6.2f} MB in {t_rec:5.2f} s   (budget 10 MB)")
    print(
        f"  recording of the journal alone  {len(built.data) / 1e6:6.2f} MB: replay {t_replay:5.2f} s + build "
        f"{built.seconds:5.2f} s (scene {built.scene_bytes / 1e6:.2f} MB, the rest viser's client and the panel)"
    )
    print(
        f"\n(frames count as drawn once the viewer got them and then nothing for {QUIET} s; that wait is not in the times)"
    )
    return 0


if __name__ == "__main__":
    sys.exit(main())
