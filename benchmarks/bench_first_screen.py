"""What a class opening the first screen at once costs: N tabs asking for the session-less 3D view together.

Run: ``PYTHONPATH=. .venv/bin/python benchmarks/bench_first_screen.py [--tabs 30] [--models ../shared/models]
[--model bunny]``.

A real workbench app (viser on), ``--tabs`` raw viser clients (tests/viewer_wire.py) each with a preview ticket
(``POST /api/viewer/preview``), all connecting at once from their own threads, while another thread asks
``/api/health`` every 50 ms. Printed: the seconds until each tab had the object and the arm (p50, p95, max),
the bytes each tab received, how many times the shared geometry was built (1 expected), ``/api/health`` latency
p50 / p95 / max during the connections, and the process's peak memory; a first wave (the geometry built on the
first tab) and a second (the geometry shared).
"""

from __future__ import annotations

import argparse
import dataclasses
import resource
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


def drawn(raw: RawViewer) -> bool:
    names = {m.get("name") for m in raw.messages()}
    return "/preview/object" in names and any(isinstance(n, str) and n.startswith("/robot/arm/") for n in names)


def pct(values: list[float], q: float) -> float:
    values = sorted(values)
    return values[min(len(values) - 1, int(q * len(values)))]


def main() -> None:
    ap = argparse.ArgumentParser(description=(__doc__ or "").splitlines()[0])
    ap.add_argument("--tabs", type=int, default=30)
    ap.add_argument("--models", type=Path, default=None, help="models directory (default: the built-in objects)")
    ap.add_argument("--model", default=None, help="the server's default model (default: the settings')")
    args = ap.parse_args()
    with tempfile.TemporaryDirectory() as tmp:
        settings = AppSettings(viser_port=0, scene=True, data_dir=Path(tmp) / "data")
        if args.models is not None:
            settings = settings.replace(models_dir=args.models)
        if args.model is not None:
            settings = settings.replace(devices=dataclasses.replace(settings.devices, model=args.model))
        with TestClient(create_app(settings), base_url="http://127.0.0.1") as client:
            health: list[float] = []
            stop = threading.Event()

            def ask_health() -> None:
                while not stop.is_set():
                    t = time.perf_counter()
                    client.get("/api/health").raise_for_status()
                    health.append(time.perf_counter() - t)
                    time.sleep(0.05)

            waits: list[float] = []
            sizes: list[int] = []
            raws: list[RawViewer] = []
            lock = threading.Lock()

            def tab() -> None:
                t = time.perf_counter()
                body = client.post("/api/viewer/preview").json()
                ticket = body["url"].split("ticket%3D")[1]
                port = body["port"]
                raw = RawViewer(f"ws://127.0.0.1:{port}/?ticket={ticket}", f"http://127.0.0.1:{port}")
                while not drawn(raw):
                    if time.perf_counter() - t > 120:
                        raise TimeoutError("a tab was not drawn in 120 s")
                    time.sleep(0.02)
                with lock:
                    waits.append(time.perf_counter() - t)
                    raws.append(raw)

            previews: Any = client.app.state.preview_views  # type: ignore[attr-defined]
            for wave in ("cold (the geometry built)", "warm (the geometry shared)"):
                health.clear()
                waits.clear()
                stop.clear()
                for raw in raws:
                    raw.close()
                raws.clear()
                pinger = threading.Thread(target=ask_health, daemon=True)
                pinger.start()
                time.sleep(0.3)
                threads = [threading.Thread(target=tab) for _ in range(args.tabs)]
                t0 = time.perf_counter()
                for th in threads:
                    th.start()
                for th in threads:
                    th.join()
                total = time.perf_counter() - t0
                time.sleep(0.5)  # the last frames in
                stop.set()
                pinger.join()
                sizes = [sum(n for _, n, _ in raw.frames) for raw in raws]
                g = previews.geometry()
                print(f"model {g.model}: {len(g.faces)} faces shown; {args.tabs} tabs at once, {wave}")
                print(f"  all drawn in {total:.2f} s; per tab to object + arm: p50 {statistics.median(waits):.2f} s, "
                      f"p95 {pct(waits, 0.95):.2f} s, max {max(waits):.2f} s")  # fmt: skip
                print(
                    f"  bytes per tab: median {statistics.median(sizes) / 1e3:.0f} kB; geometry built {previews.builds}x"
                )
                print(f"  /api/health during it ({len(health)} asks): p50 {1e3 * statistics.median(health):.1f} ms, "
                      f"p95 {1e3 * pct(health, 0.95):.1f} ms, max {1e3 * max(health):.1f} ms")  # fmt: skip
            print(f"peak memory of the process: {resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1e3:.0f} MB")
            for raw in raws:
                raw.close()


if __name__ == "__main__":
    main()
