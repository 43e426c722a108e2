"""``kill -9`` a real ``nbv serve`` process in the middle of two sessions, restart it, resume both.

Session A waits with a pending plan; session B is in auto mode when the SIGKILL lands (its step in flight is
lost, nothing else). After the restart both are listed, and resuming them rebuilds the same voxel map and the
same pending plan as before the kill (A) or as the journal last recorded (B).
"""

from __future__ import annotations

import json
import os
import signal
import time
from pathlib import Path
from typing import Any

import httpx
import numpy as np
import pytest
from apphelpers import SMALL

from tests.helpers import SMALL_CAMERA
from tests.servers import serve_process

pytestmark = pytest.mark.slow


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
    with serve_process(data, models_dir, log) as (proc, api):
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

    with serve_process(data, models_dir, log) as (_, api):
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
