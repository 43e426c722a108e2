"""What one tab's 3D viewer receives: bytes per plan and per approve, and how long until a change is drawn.

Run: ``PYTHONPATH=. .venv/bin/python benchmarks/bench_scene.py [--steps 5] [--models ../shared/models]``.

A real workbench app (viser on), one raw viser client bound by a viewer ticket (tests/viewer_wire.py: it
counts the bytes of every websocket frame it receives and decodes them), and for each model (the Stanford
bunny, the built-in L-block) at resolution 0.01 m with the paper's other defaults: capture, then ``--steps``
times plan + approve of the planner's choice. Printed per model (medians over the steps, max in brackets):

- bytes per plan / per approve: what the viewer received after the request until it went quiet (with the
  arm's animation, given apart too);
- approve->drawn: from the approve request until the last frame of its scene update arrived, and the part of
  it after the approve answered (the capture itself is the rest); the frames that only move the arm (the
  executed move played back at its own speed, about a second) are timed apart ("arm animation ends");
- plan->drawn: from the plan request until its frames arrived, and the part after the plan answered;
- approve->next plan drawn: approve, then plan, until the plan is drawn, minus the two requests' own time;
- status pushed: when the page's event stream (``/api/events``) delivered the ``captured`` / ``planned``
  status, relative to the answer of the request that caused it (negative: before the answer).

Budget: median bytes per approve on the bunny at 0.01 m <= 150 kB; approve click -> next plan drawn
<= capture time + 0.5 s (the plan's own computation aside).
"""

from __future__ import annotations

import argparse
import statistics
import sys
import tempfile
import threading
import time
from pathlib import Path
from typing import Any

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from fastapi.testclient import TestClient

from app.main import create_app
from app.settings import AppSettings
from tests.viewer_wire import RawViewer

QUIET = 0.4
"""Seconds without a new frame after which an update counts as fully received."""


def animation(messages: list[dict[str, Any]]) -> bool:
    """Whether a frame only moves the arm (``/robot/...``: the executed move played back in the 3D view)."""
    return bool(messages) and all(str(m.get("name", "")).startswith("/robot") for m in messages)


def settle(raw: RawViewer, since: int, timeout: float = 60.0) -> tuple[float, float | None]:
    """Wait until ``raw`` got at least one frame after ``since`` and then none for QUIET s: (the last frame of
    the session's scene, the last frame of the arm's animation or None). The arm's animation plays the
    executed move at its own speed (seconds); the scene's update does not wait for it."""
    deadline = time.perf_counter() + timeout
    while time.perf_counter() < deadline:
        frames = raw.frames[since:]
        if frames and time.perf_counter() - frames[-1][0] > QUIET:
            scene = [t for t, _, ms in frames if not animation(ms)]
            arm = [t for t, _, ms in frames if animation(ms)]
            return (scene[-1] if scene else frames[0][0]), (arm[-1] if arm else None)
        time.sleep(0.02)
    raise TimeoutError("the viewer received nothing")


class EventLog:
    """The page's event stream of one session, read in a thread: (arrival time, event) of each status."""

    def __init__(self, client: TestClient, sid: str) -> None:
        self.items: list[tuple[float, str]] = []
        self._cm = client.websocket_connect(f"/api/events?session={sid}")
        self.ws = self._cm.__enter__()
        self._thread = threading.Thread(target=self._read, daemon=True)
        self._thread.start()

    def _read(self) -> None:
        try:
            while True:
                m = self.ws.receive_json()
                if m.get("type") == "status":
                    self.items.append((time.perf_counter(), m["event"]))
        except Exception:
            return

    def first_after(self, t0: float, event: str) -> float | None:
        hits = [t for t, e in list(self.items) if t >= t0 and e == event]
        return hits[0] if hits else None

    def close(self) -> None:
        self._cm.__exit__(None, None, None)


def run(client: TestClient, model: str, steps: int) -> dict[str, list[float]]:
    config = {"voxel": {"resolution": 0.01}}
    sid = client.post("/api/sessions", json={"model": model, "config": config}).json()["id"]
    events = EventLog(client, sid)
    v = client.post("/api/viewer", json={"session": sid}).json()
    port = v["port"]
    raw = RawViewer(f"ws://127.0.0.1:{port}/?ticket={v['url'].split('ticket%3D')[1]}", f"http://127.0.0.1:{port}")
    out: dict[str, list[float]] = {k: [] for k in ("plan_bytes", "approve_bytes", "approve_http", "approve_after",
                                                   "approve_drawn", "plan_http", "plan_after", "plan_drawn",
                                                   "next_plan_overhead", "push_vs_answer", "animation_bytes",
                                                   "animation_after")}  # fmt: skip
    try:
        settle(raw, 0)
        mark = raw.mark()
        client.post(f"/api/sessions/{sid}/capture")
        settle(raw, mark)
        plan = None
        for step in range(steps + 1):
            mark = raw.mark()
            t0 = time.perf_counter()
            plan = client.post(f"/api/sessions/{sid}/plan").json()
            t1 = time.perf_counter()
            drawn, _ = settle(raw, mark)
            pushed = events.first_after(t0, "planned")
            if pushed is not None:
                out["push_vs_answer"].append(pushed - t1)
            out["plan_bytes"].append(raw.bytes_since(mark))
            out["plan_http"].append(t1 - t0)
            out["plan_after"].append(max(0.0, drawn - t1))
            out["plan_drawn"].append(drawn - t0)
            if step > 0:  # approve -> next plan drawn, minus the approve's and the plan's own time
                out["next_plan_overhead"].append(out["approve_after"][-1] + out["plan_after"][-1])
            if step == steps or plan["best"] is None:
                break
            mark = raw.mark()
            t0 = time.perf_counter()
            r = client.post(
                f"/api/sessions/{sid}/approve", json={"plan_id": plan["plan_id"], "index": plan["best"]["index"]}
            )
            t1 = time.perf_counter()
            assert r.status_code == 200, r.text
            drawn, animated = settle(raw, mark)
            pushed = events.first_after(t0, "captured")
            if pushed is not None:
                out["push_vs_answer"].append(pushed - t1)
            out["approve_bytes"].append(raw.bytes_since(mark))
            out["animation_bytes"].append(sum(n for _, n, ms in raw.frames[mark:] if animation(ms)))
            if animated is not None:
                out["animation_after"].append(animated - t1)
            out["approve_http"].append(t1 - t0)
            out["approve_after"].append(max(0.0, drawn - t1))
            out["approve_drawn"].append(drawn - t0)
    finally:
        raw.close()
        client.delete(f"/api/sessions/{sid}")
        events.close()
    return out


def fmt(values: list[float], unit: str) -> str:
    if not values:
        return "–"
    med, top = statistics.median(values), max(values)
    if unit == "kB":
        return f"{med / 1000:8.1f} kB [{top / 1000:7.1f}]"
    return f"{med:7.3f} s [{top:6.3f}]"


def main() -> int:
    p = argparse.ArgumentParser(description=(__doc__ or "").splitlines()[0])
    p.add_argument("--steps", type=int, default=5, help="plan + approve rounds per model")
    p.add_argument("--models", type=Path, default=Path("../shared/models"))
    args = p.parse_args()
    with tempfile.TemporaryDirectory() as tmp:
        settings = AppSettings(viser_port=0, scene=True, models_dir=args.models, data_dir=Path(tmp))
        with TestClient(create_app(settings), base_url="http://127.0.0.1") as client:
            names = [m["name"] for m in client.get("/api/models").json()]
            models = [*[n for n in names if n.startswith("bunny")][:1], "l-block"]
            print(f"{args.steps} rounds of plan + approve per model, resolution 0.01 m; medians [max]")
            for model in models:
                r: dict[str, Any] = run(client, model, args.steps)
                print(f"\n{model}")
                print(f"  bytes per plan            {fmt(r['plan_bytes'], 'kB')}")
                print(
                    f"  bytes per approve         {fmt(r['approve_bytes'], 'kB')}   of which the arm's animation {fmt(r['animation_bytes'], 'kB')}"
                )
                print(f"  approve request (capture) {fmt(r['approve_http'], 's')}")
                print(
                    f"  approve -> drawn          {fmt(r['approve_drawn'], 's')}   after the answer {fmt(r['approve_after'], 's')}"
                )
                print(
                    f"  arm animation ends        {fmt(r['animation_after'], 's')} after the approve's answer (the move played back)"
                )
                print(f"  plan request              {fmt(r['plan_http'], 's')}")
                print(
                    f"  plan -> drawn             {fmt(r['plan_drawn'], 's')}   after the answer {fmt(r['plan_after'], 's')}"
                )
                print(f"  approve -> next plan drawn, beyond capture + plan time {fmt(r['next_plan_overhead'], 's')}")
                print(f"  status pushed, relative to the request's answer         {fmt(r['push_vs_answer'], 's')}")
    print(
        f"\n(frames count as drawn once the viewer got them and then nothing for {QUIET} s; that wait is not in the times;"
        "\n the scene's times leave out the frames that only move the arm, its animation is given apart)"
    )
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
