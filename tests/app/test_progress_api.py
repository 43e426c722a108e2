"""Progress and stopping over HTTP: a plan's stages pushed on /api/events, POST .../stop kills a running plan
(the plan request answers 409, the state goes back), a create's stages on /api/events?create=ID and its
cancellation by DELETE /api/creations/ID (nothing created), a resume's replay pushed to its session's tab."""

from __future__ import annotations

import json
import threading
from pathlib import Path
from typing import Any

import httpx
import pytest
import trimesh
import websockets.sync.client
from apphelpers import BASE_URL, SMALL, free_port, running_server
from fastapi.testclient import TestClient

from app.main import create_app
from app.settings import AppSettings

HEAVY: dict[str, Any] = {
    "voxel": {"resolution": 0.01},
    "cluster": {"search": "exhaustive", "t_min": 1, "t_max": 60, "max_iter": 1000, "tol": 1e-8},
    "candidates": {"count": 833, "parallels": 30},
}


def receive_until(ws: Any, predicate: Any, timeout: float = 60.0) -> list[dict[str, Any]]:
    """Messages until one satisfies ``predicate`` (that one last)."""
    seen = []
    while True:
        m = json.loads(ws.recv(timeout=timeout))
        seen.append(m)
        if predicate(m):
            return seen


def post_in_thread(url: str, body: Any = None) -> tuple[threading.Thread, dict[str, Any]]:
    box: dict[str, Any] = {}

    def run() -> None:
        box["response"] = httpx.post(url, json=body, timeout=120)

    thread = threading.Thread(target=run, daemon=True)
    thread.start()
    return thread, box


@pytest.mark.slow
def test_a_plans_progress_is_pushed_and_stop_ends_it(settings: AppSettings) -> None:
    with running_server(settings.replace(port=free_port())) as live:
        api = httpx.Client(base_url=live.url, timeout=120)
        sid = api.post("/api/sessions", json={"config": HEAVY}).json()["id"]
        assert api.post(f"/api/sessions/{sid}/capture").status_code == 200
        ws_url = live.url.replace("http", "ws") + f"/api/events?session={sid}"
        with websockets.sync.client.connect(ws_url) as ws:
            receive_until(ws, lambda m: m["type"] == "status")
            thread, box = post_in_thread(f"{live.url}/api/sessions/{sid}/plan")
            seen = receive_until(
                ws,
                lambda m: (
                    m["type"] == "progress" and m["progress"]["stage"] == "fit occupied" and m["progress"]["done"] >= 2
                ),
            )
            progress = [m["progress"] for m in seen if m["type"] == "progress"]
            stages = [p["stage"] for p in progress]
            assert stages[0] == "starting" and "reachability" in stages and progress[-1]["total"] == 60  # T = 1..60
            assert all(p["operation"] == "plan" and p["stoppable"] for p in progress[1:]) and progress[-1]["steps"] == 6
            assert api.get(f"/api/sessions/{sid}").json()["progress"]["stage"] == "fit occupied"
            st = api.post(f"/api/sessions/{sid}/stop").json()
            thread.join(10)
            r = box["response"]
            assert r.status_code == 409 and "stopped" in r.json()["detail"], r.text
            seen = receive_until(ws, lambda m: m["type"] == "status" and m["status"]["state"] == "ready")
            assert {"type": "progress", "progress": None} in seen
        st = api.get(f"/api/sessions/{sid}").json()
        assert (st["state"], st["progress"], st["pending_plan"], st["error"]) == ("ready", None, None, None)


def test_a_creates_progress_is_pushed_and_delete_cancels_it(settings: AppSettings, models_dir: Path) -> None:
    trimesh.creation.icosphere(subdivisions=6, radius=0.05).export(models_dir / "ball.obj")
    with running_server(settings.replace(port=free_port())) as live:
        api = httpx.Client(base_url=live.url, timeout=120)
        ws_url = live.url.replace("http", "ws") + "/api/events?create=tab-create-1"
        with websockets.sync.client.connect(ws_url) as ws:
            r = api.post("/api/sessions", json={"model": "ball.obj", "config": SMALL, "progress_id": "tab-create-1"})
            assert r.status_code == 201, r.text
            seen = receive_until(ws, lambda m: m["type"] == "create" and m["progress"] is None)
        stages = [m["progress"]["stage"] for m in seen if m["type"] == "create" and m["progress"]]
        assert [s for i, s in enumerate(stages) if i == 0 or stages[i - 1] != s] == [
            "checking the file",
            "reading the mesh",
            "checking the mesh",
            "sampling its surface",
            "building the cell",
            "starting the session",
        ]
        # cancelled while it reads the mesh (held there until the DELETE answered): 409, no session, the id free
        hold = threading.Event()

        def hold_reading(progress_id: str, progress: Any) -> None:
            if progress_id == "tab-create-2" and progress is not None and progress.stage == "reading the mesh":
                hold.wait(30)

        live.registry.creations.listeners.append(hold_reading)
        with websockets.sync.client.connect(ws_url.replace("tab-create-1", "tab-create-2")) as ws:
            thread, box = post_in_thread(
                f"{live.url}/api/sessions", {"model": "ball.obj", "config": SMALL, "progress_id": "tab-create-2"}
            )
            receive_until(ws, lambda m: m["type"] == "create" and m["progress"] is not None)
            assert api.delete("/api/creations/tab-create-2").status_code == 204
            hold.set()
            thread.join(60)
        r = box["response"]
        assert r.status_code == 409 and "cancelled" in r.json()["detail"], r.text
        assert len(api.get("/api/sessions").json()) == 1
        missing = api.delete("/api/creations/tab-create-2")
        assert missing.status_code == 404 and "none is running" in missing.json()["detail"]
        bad = api.post("/api/sessions", json={"progress_id": "no spaces allowed"})
        assert bad.status_code == 422 and "progress_id" in bad.text


def test_a_resume_pushes_its_replay_to_the_tab_of_its_session(settings: AppSettings) -> None:
    with TestClient(create_app(settings), base_url=BASE_URL) as a:
        sid = a.post("/api/sessions", json={"config": SMALL}).json()["id"]
        a.post(f"/api/sessions/{sid}/capture")
        assert a.post(f"/api/sessions/{sid}/step", json={"count": 2}).status_code == 200
    with TestClient(create_app(settings), base_url=BASE_URL) as b:  # the server restarted
        with b.websocket_connect(f"/api/events?session={sid}") as ws:
            assert ws.receive_json()["status"]["state"] == "interrupted"
            assert b.post(f"/api/sessions/{sid}/resume").status_code == 200
            seen = []
            while not (seen and seen[-1]["type"] == "status" and seen[-1]["status"]["state"] != "interrupted"):
                seen.append(ws.receive_json())
        progress = [m["progress"] for m in seen if m["type"] == "progress"]
        assert progress[-1] is None and {p["operation"] for p in progress[:-1]} == {"resume"}
        assert progress[-2]["stage"] == "replaying the journal" and progress[-2]["done"] == progress[-2]["total"] == 5
