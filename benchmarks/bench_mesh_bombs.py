"""Mesh bombs against a running server: refusal time, the server's RSS growth, /api/health latency.

Starts ``nbv serve`` on 127.0.0.1 (a free port, a temporary data and models directory), then for instancing
GLBs of 400, 1,500 and 5,000 nodes (one 20k-triangle mesh used by N nodes) and for OBJ / PLY parser bombs:
uploads each (``POST /api/models``), and creates a session of each put in the models directory
(``POST /api/sessions``), while a thread samples ``GET /api/health`` every 100 ms and another the server's
VmRSS every 20 ms. Goals: refused in < 2 s, RSS growth < 200 MB, health < 1 s. The last row,
a 17 MB OBJ that parses for seconds, shows the server answering health while the child reads.

    .venv/bin/python benchmarks/bench_mesh_bombs.py
"""

from __future__ import annotations

import os
import socket
import subprocess
import sys
import tempfile
import threading
import time
from collections.abc import Callable
from pathlib import Path

import httpx

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
from tests.mesh_bombs import instancing_glb, obj_parser_bomb, obj_slow_parse, ply_header_bomb


def free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def rss_mb(pid: int) -> float:
    with open(f"/proc/{pid}/status") as fh:
        for line in fh:
            if line.startswith("VmRSS:"):
                return int(line.split()[1]) / 1024
    return 0.0


class Sampler:
    """Calls ``probe`` every ``period`` seconds in a thread and keeps the results."""

    def __init__(self, probe: Callable[[], float], period: float) -> None:
        self.probe, self.period, self.samples = probe, period, []
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._run, daemon=True)

    def _run(self) -> None:
        while not self._stop.is_set():
            self.samples.append(self.probe())
            self._stop.wait(self.period)

    def __enter__(self) -> Sampler:
        self._thread.start()
        return self

    def __exit__(self, *exc: object) -> None:
        self._stop.set()
        self._thread.join(10)


def main() -> None:
    root = Path(tempfile.mkdtemp(prefix="nbv-bombs-"))
    models = root / "models"
    models.mkdir()
    bombs = {f"glb-{n}.glb": instancing_glb(n) for n in (400, 1_500, 5_000)}
    bombs["obj-bomb.obj"] = obj_parser_bomb()
    bombs["ply-bomb.ply"] = ply_header_bomb()
    bombs["obj-slow.obj"] = obj_slow_parse()  # not a bomb: a big file, read in the child while health answers
    for name, data in bombs.items():
        (models / name).write_bytes(data)
    port = free_port()
    nbv = Path(sys.executable).with_name("nbv")
    server = subprocess.Popen(
        [str(nbv), "serve", "--port", str(port), "--viser-port", str(free_port()), "--models-dir", str(models),
         "--data-dir", str(root / "data"), "--log-level", "warning"],
    )  # fmt: skip
    url = f"http://127.0.0.1:{port}"
    try:
        client = httpx.Client(base_url=url, timeout=120)
        for _ in range(300):
            try:
                if client.get("/api/health").status_code == 200:
                    break
            except httpx.HTTPError:
                time.sleep(0.2)
        client.post("/api/models", files={"file": ("warm.glb", instancing_glb(1, 200))})  # start the forkserver
        print(f"server pid {server.pid}, RSS at start {rss_mb(server.pid):.0f} MB")
        print(f"{'file':<14} {'kB':>6} {'via':<7} {'status':>6} {'refused s':>9} {'RSS +MB':>8} {'health max s':>12}")
        for name, data in bombs.items():
            for via in ("upload", "create"):
                base = rss_mb(server.pid)

                def health() -> float:
                    t0 = time.monotonic()
                    try:
                        httpx.get(f"{url}/api/health", timeout=10)
                    except httpx.HTTPError:
                        return 10.0
                    return time.monotonic() - t0

                with Sampler(health, 0.1) as h, Sampler(lambda: rss_mb(server.pid), 0.02) as r:
                    t0 = time.monotonic()
                    if via == "upload":
                        answer = client.post("/api/models", files={"file": (name, data)})
                    else:
                        answer = client.post("/api/sessions", json={"model": name})
                    took = time.monotonic() - t0
                    time.sleep(0.3)
                growth = max(r.samples) - base
                print(
                    f"{name:<14} {len(data) / 1e3:>6.0f} {via:<7} {answer.status_code:>6} {took:>9.2f} "
                    f"{growth:>8.0f} {max(h.samples):>12.3f}   {answer.json().get('detail', '')[:90]}"
                )
        print(f"RSS at the end {rss_mb(server.pid):.0f} MB")
    finally:
        server.terminate()
        server.wait(30)


if __name__ == "__main__":
    os.nice(5)
    main()
