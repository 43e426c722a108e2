"""``kill -9`` a real ``nbv serve`` process in the middle of two sessions, restart it, resume both.

Session A waits with a pending plan; session B is in auto mode when the SIGKILL lands (its step in flight is
lost, nothing else). After the restart both are listed, and resuming them rebuilds the same voxel map and the
same pending plan as before the kill (A) or as the journal last recorded (B).
"""

from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
import time
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path
from typing import Any

import httpx
import numpy as np
import pytest
from apphelpers import SMALL, free_port

from tests.helpers import SMALL_CAMERA, small_camera_toml

pytestmark = pytest.mark.slow
REPO = Path(__file__).resolve().parents[2]


@contextmanager
def nbv_serve(data_dir: Path, models_dir: Path, log: Path) -> Iterator[tuple[subprocess.Popen, httpx.Client]]:
    port = free_port()
    config = data_dir.parent / "serve.toml"  # the API tests' small camera (tests/helpers.py SMALL_CAMERA)
    config.write_text(small_camera_toml())
    cmd = [sys.executable, "-m", "nbv.cli", "serve", "--port", str(port), "--viser-port", "0", "--config", str(config)]
    cmd += ["--data-dir", str(data_dir), "--models-dir", str(models_dir), "--log-level", "warning"]
    with open(log, "ab") as out:
        proc = subprocess.Popen(cmd, cwd=REPO, stdout=out, stderr=subprocess.STDOUT)
    client = httpx.Client(base_url=f"http://127.0.0.1:{port}", timeout=60)
    try:
        deadline = time.time() + 90
        while True:
            try:
                if client.get("/api/health").status_code == 200:
                    break
            except httpx.TransportError:
                pass
            if proc.poll() is not None or time.time() > deadline:
                raise RuntimeError(f"nbv serve did not start: {log.read_text()[-2000:]}")
            time.sleep(0.1)
        yield proc, client
    finally:
        client.close()
        if proc.poll() is None:
            proc.kill()
        proc.wait(30)


def snapshot(client: httpx.Client, sid: str) -> dict[str, Any]:
    st = client.get(f"/api/sessions/{sid}").json()
    plan = st["pending_plan"]
    return {
        "iteration": st["iteration"],
        "points": st["points"],
        "voxels": st["voxels"],
        "plan_id": plan and plan["plan_id"],
        "best": plan and plan["best"],
        "scores": plan and [c["score"] for c in client.get(f"/api/sessions/{sid}/candidates").json()],
        "cloud": client.get(f"/api/sessions/{sid}/cloud.ply").content,
    }


def test_kill_9_mid_session_then_resume(tmp_path: Path, models_dir: Path) -> None:
    data, log = tmp_path / "data", tmp_path / "serve.log"
    with nbv_serve(data, models_dir, log) as (proc, api):
        a = api.post("/api/sessions", json={"config": SMALL, "seed": 11}).json()["id"]
        api.post(f"/api/sessions/{a}/capture")
        plan = api.post(f"/api/sessions/{a}/plan").json()
        api.post(f"/api/sessions/{a}/approve", json={"plan_id": plan["plan_id"], "index": plan["best"]["index"]})
        plan_a = api.post(f"/api/sessions/{a}/plan").json()
        before_a = snapshot(api, a)

        b = api.post("/api/sessions", json={"config": SMALL, "seed": 12}).json()["id"]
        api.post(f"/api/sessions/{b}/capture")
        assert api.post(f"/api/sessions/{b}/auto", json={"count": 8}).status_code == 202
        deadline = time.time() + 60
        while api.get(f"/api/sessions/{b}").json()["iteration"] < 3:
            assert time.time() < deadline
            time.sleep(0.01)
        os.kill(proc.pid, signal.SIGKILL)  # in the middle of B's next step
        proc.wait(30)
        assert proc.returncode == -signal.SIGKILL

    journal_b = [json.loads(line) for line in (data / "sessions" / b / "journal.jsonl").read_text().splitlines()]
    captures_b = [e for e in journal_b if e["kind"] == "capture"]
    plans_b = [e for e in journal_b if e["kind"] == "plan"]
    assert journal_b[-1]["kind"] != "auto_stop"  # killed, not stopped
    with np.load(data / "sessions" / b / captures_b[0]["frame"]) as frame:  # the config file's camera was used
        assert frame["depth"].shape == (SMALL_CAMERA.height, SMALL_CAMERA.width)

    with nbv_serve(data, models_dir, log) as (_, api):
        listed = {s["id"]: s for s in api.get("/api/sessions").json()}
        assert set(listed) == {a, b} and {s["state"] for s in listed.values()} == {"interrupted"}
        assert listed[a]["iteration"] == 2 and listed[b]["iteration"] == len(captures_b) >= 3

        r = api.post(f"/api/sessions/{a}/resume").json()
        assert r["verified"] and r["interrupted"] is None
        assert snapshot(api, a) == before_a  # same map, cloud, pending plan_id, best index and score, all scores
        body = {"plan_id": plan_a["plan_id"], "index": plan_a["best"]["index"]}
        assert api.post(f"/api/sessions/{a}/approve", json=body).json()["iteration"] == 3

        r = api.post(f"/api/sessions/{b}/resume").json()
        assert r["verified"], r["mismatches"]
        st = r["session"]
        assert st["iteration"] == len(captures_b) and st["voxels"] == captures_b[-1]["voxels"]
        assert st["points"] == captures_b[-1]["points"] and st["state"] in ("ready", "planned")
        if st["pending_plan"] is not None:  # the kill came after a plan: it is pending again, as journaled
            assert st["pending_plan"]["plan_id"] == plans_b[-1]["plan_id"]
            assert st["pending_plan"]["best"]["index"] == plans_b[-1]["best"]["index"]
            assert st["pending_plan"]["best"]["score"] == plans_b[-1]["best"]["score"]
        assert api.post(f"/api/sessions/{b}/step").json()["iteration"] == len(captures_b) + 1
