"""A class on one server: N seats (default 30) stepping at once over REST, as a classroom does.

Starts ``nbv serve`` on a free 127.0.0.1 port (its own data directory, removed after), creates a class of N seats
(``POST /api/classes``), then every seat, in a thread of its own, joins, captures and steps ``--steps`` times
(``POST .../step``), all at once; meanwhile ``/api/health`` is asked every 0.2 s and the memory of the server and
its worker processes is sampled every second. Prints: the class create time, health latency p50/p95/max, step
time p50/p95/max, every step answered or not, and peak memory (server, workers, total) with the live and sleeping
seat counts. Bounded: loopback only, ``--timeout`` s per request, and the whole run stops after ``--minutes``.

    .venv/bin/python benchmarks/bench_class.py [--seats 30] [--steps 3] [--max-live 16] [--idle-sleep 0]

``--max-class-seats`` below ``--seats`` is refused by the server (422); ``--max-live`` below the seats does not
keep seats from being live (a class raises the limit), ``--idle-sleep S`` puts seats idle for S s to sleep, and
``--think T`` makes each seat wait T s between its steps (a student reading): with T > S seats sleep and wake.
"""

from __future__ import annotations

import argparse
import contextlib
import shutil
import socket
import statistics
import subprocess
import sys
import tempfile
import threading
import time
from pathlib import Path
from typing import Any

import httpx
import psutil

REPO = Path(__file__).resolve().parents[1]


def free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return int(s.getsockname()[1])


def pct(values: list[float], q: float) -> float:
    if not values:
        return float("nan")
    ordered = sorted(values)
    return ordered[min(len(ordered) - 1, round(q * (len(ordered) - 1)))]


def rss_mb(proc: psutil.Process) -> tuple[float, float, int]:
    """(server MB, workers MB, worker count): resident memory of the server and of its child processes."""
    try:
        server = proc.memory_info().rss / 1e6
        children = proc.children(recursive=True)
    except psutil.Error:
        return 0.0, 0.0, 0
    workers = 0.0
    for child in children:
        with contextlib.suppress(psutil.Error):
            workers += child.memory_info().rss / 1e6
    return server, workers, len(children)


def main() -> None:
    parser = argparse.ArgumentParser(description="a class of seats stepping at once over REST")
    parser.add_argument("--seats", type=int, default=30)
    parser.add_argument("--steps", type=int, default=3, help="steps each seat takes after its first capture")
    parser.add_argument("--model", default="l-block")
    parser.add_argument("--max-live", type=int, default=16, help="server.max_live_sessions")
    parser.add_argument("--max-class-seats", type=int, default=40)
    parser.add_argument("--idle-sleep", type=float, default=0.0, help="server.idle_sleep (0: never)")
    parser.add_argument("--think", type=float, default=0.0, help="seconds a seat waits between its steps")
    parser.add_argument("--timeout", type=float, default=300.0, help="seconds a request may take")
    parser.add_argument("--minutes", type=float, default=15.0, help="the whole run stops after this long")
    args = parser.parse_args()

    data = Path(tempfile.mkdtemp(prefix="nbv-bench-class-"))
    port = free_port()
    cmd = [sys.executable, "-m", "nbv.cli", "serve", "--host", "127.0.0.1", "--port", str(port)]
    cmd += ["--viser-port", "0", "--data-dir", str(data / "data"), "--log-level", "warning"]
    cmd += ["--server.max_live_sessions", str(args.max_live), "--server.max_class_seats", str(args.max_class_seats)]
    cmd += ["--server.idle_sleep", str(args.idle_sleep)]
    log = open(data / "serve.log", "wb")  # noqa: SIM115 - closed in finally
    server = subprocess.Popen(cmd, cwd=REPO, stdout=log, stderr=subprocess.STDOUT)
    deadline = time.monotonic() + args.minutes * 60
    stop = threading.Event()
    health: list[float] = []
    health_failures: list[str] = []
    memory: list[tuple[float, float, int]] = []
    steps: list[float] = []
    failures: list[str] = []
    lock = threading.Lock()
    room: dict[str, Any] = {}
    asleep: list[int] = []  # seats asleep at each look at the board
    url = f"http://127.0.0.1:{port}"
    try:
        with httpx.Client(base_url=url, timeout=args.timeout) as client:
            while True:
                try:
                    if client.get("/api/health").status_code == 200:
                        break
                except httpx.TransportError:
                    pass
                if server.poll() is not None or time.monotonic() > deadline:
                    raise SystemExit(f"the server did not start: {(data / 'serve.log').read_text()[-2000:]}")
                time.sleep(0.2)
            proc = psutil.Process(server.pid)
            print(f"server up (pid {server.pid}); memory idle: server {rss_mb(proc)[0]:.0f} MB", flush=True)

            def watch_health() -> None:
                with httpx.Client(base_url=url, timeout=10) as c:
                    while not stop.is_set():
                        t = time.perf_counter()
                        try:
                            ok = c.get("/api/health").status_code == 200
                        except httpx.TransportError as exc:
                            ok = False
                            health_failures.append(str(exc))
                        if ok:
                            health.append(time.perf_counter() - t)
                        stop.wait(0.2)

            def watch_memory() -> None:
                with httpx.Client(base_url=url, timeout=30) as c:
                    while not stop.is_set():
                        memory.append(rss_mb(proc))
                        if room:
                            with contextlib.suppress(httpx.HTTPError, KeyError, ValueError):
                                seen = c.get(f"/api/classes/{room['id']}").json()["seats"]
                                asleep.append(sum(s["asleep"] for s in seen))
                        stop.wait(1.0)

            watchers = [threading.Thread(target=f, daemon=True) for f in (watch_health, watch_memory)]
            for w in watchers:
                w.start()

            t0 = time.perf_counter()
            made = client.post("/api/classes", json={"seats": args.seats, "model": args.model})
            create_s = time.perf_counter() - t0
            if made.status_code != 201:
                raise SystemExit(f"class not created: {made.status_code} {made.text}")
            room.update(made.json())
            print(
                f"class of {args.seats} seats created in {create_s:.1f} s (live limit {room['live_limit']})", flush=True
            )

            def seat_run(number: int) -> None:
                with httpx.Client(base_url=url, timeout=args.timeout) as c:
                    sid = c.post("/api/classes/join", json={"code": room["code"]}).json()["session"]
                    for k in range(args.steps + 1):
                        if time.monotonic() > deadline:
                            with lock:
                                failures.append(f"seat {number}: stopped at the time limit")
                            return
                        path = f"/api/sessions/{sid}/" + ("capture" if k == 0 else "step")
                        t = time.perf_counter()
                        try:
                            r = c.post(path, json=None if k == 0 else {"count": 1})
                            answered = r.status_code == 200
                            why = f"{r.status_code} {r.text[:200]}"
                        except httpx.HTTPError as exc:
                            answered, why = False, repr(exc)
                        took = time.perf_counter() - t
                        if args.think > 0 and k < args.steps:
                            time.sleep(args.think)  # a student reads the page: an idle seat may sleep meanwhile
                        with lock:
                            if answered:
                                if k > 0:
                                    steps.append(took)
                            else:
                                failures.append(f"seat {number} {path.rsplit('/', 1)[1]}: {why}")

            t0 = time.perf_counter()
            seats = [threading.Thread(target=seat_run, args=(n,)) for n in range(1, args.seats + 1)]
            for t in seats:
                t.start()
            for t in seats:
                t.join()
            run_s = time.perf_counter() - t0
            board = client.get(f"/api/classes/{room['id']}").json()
            stop.set()
            for w in watchers:
                w.join(5)
    finally:
        stop.set()
        server.terminate()
        try:
            server.wait(60)
        except subprocess.TimeoutExpired:
            server.kill()
        log.close()
        shutil.rmtree(data, ignore_errors=True)

    expected = args.seats * args.steps
    peak = max(memory, key=lambda m: m[0] + m[1]) if memory else (0.0, 0.0, 0)
    views = [s["views"] for s in board["seats"]]
    print(
        f"seats {args.seats}, steps each {args.steps}, model {args.model}, load {Path('/proc/loadavg').read_text().split()[:3]}"
    )
    print(f"create class: {create_s:.1f} s ({create_s / args.seats:.2f} s a seat)")
    print(f"all seats stepping: {run_s:.1f} s wall")
    print(f"steps answered: {len(steps)}/{expected}; failures: {len(failures)}")
    for f in failures[:10]:
        print("  ", f)
    print(
        f"step time s: p50 {pct(steps, 0.5):.2f}  p95 {pct(steps, 0.95):.2f}  max {max(steps, default=float('nan')):.2f}"
    )
    print(
        f"health latency s: p50 {pct(health, 0.5):.3f}  p95 {pct(health, 0.95):.3f}  max {max(health, default=0):.3f}"
        f"  ({len(health)} asked, {len(health_failures)} failed)"
    )
    print(
        f"peak memory MB: server {peak[0]:.0f}  workers {peak[1]:.0f} ({peak[2]} processes)  total {peak[0] + peak[1]:.0f}"
        f"  (max server alone {max(m[0] for m in memory):.0f}, max workers alone {max(m[1] for m in memory):.0f})"
    )
    print(f"seats asleep on the board: max {max(asleep, default=0)} ({len(asleep)} looks)")
    print(
        f"board at the end: {board['live']} live, {sum(s['asleep'] for s in board['seats'])} asleep, views per seat "
        f"min {min(views)} mean {statistics.mean(views):.1f} max {max(views)}"
    )


if __name__ == "__main__":
    main()
