"""The journal through the API: every event on disk as it happens, in the documented format."""

from __future__ import annotations

import json

from apphelpers import SMALL, registry_of
from fastapi.testclient import TestClient

from app.settings import AppSettings
from devices.frames import load_frame
from workbench.journal.store import JOURNAL_FILE


def events_of(settings: AppSettings, sid: str) -> list[dict]:
    path = settings.data_dir / "sessions" / sid / JOURNAL_FILE
    return [json.loads(line) for line in path.read_text().splitlines()]


def test_every_step_is_journaled_as_it_happens(client: TestClient, settings: AppSettings) -> None:
    faults = {"schedule": [{"kind": "capture_failure", "at": 3}]}
    sid = client.post("/api/sessions", json={"config": SMALL, "seed": 7, "faults": faults}).json()["id"]
    client.post(f"/api/sessions/{sid}/capture")
    plan = client.post(f"/api/sessions/{sid}/plan").json()
    cands = client.get(f"/api/sessions/{sid}/candidates").json()
    other = next(c["index"] for c in cands if c["eligible"] and c["index"] != plan["best"]["index"])
    client.post(f"/api/sessions/{sid}/approve", json={"plan_id": plan["plan_id"], "index": other})
    assert client.patch(f"/api/sessions/{sid}/config", json={"termination": {"max_views": 6}}).status_code == 200
    assert client.post(f"/api/sessions/{sid}/step").status_code == 503  # capture 3 fails
    assert client.post(f"/api/sessions/{sid}/retry").status_code == 200
    # each event is on disk when the request returns, not at shutdown
    events = events_of(settings, sid)
    kinds = [e["kind"] for e in events]
    assert kinds == [
        *("session", "capture", "plan", "decision", "capture", "config"),
        *("plan", "decision", "error", "retry", "capture"),
    ]
    assert [e["seq"] for e in events] == list(range(len(events)))
    head = events[0]
    assert (head["format"], head["version"], head["id"], head["seed"]) == ("nbv-journal", 1, sid, 7)
    assert head["model"] == {"name": "l-block", "kind": "builtin"} and head["source"] == {"kind": "sim"}
    assert head["config"]["voxel"]["resolution"] == 0.02 and head["config"]["cluster"]["seed"] == 7
    assert head["devices"]["seed"] == 7 and head["faults"]["schedule"] == faults["schedule"]
    captures = [e for e in events if e["kind"] == "capture"]
    assert [c["iteration"] for c in captures] == [1, 2, 3]
    assert [c["decision"] for c in captures] == ["initial", "override", "step"]
    wb = registry_of(client).get(sid)
    assert captures[-1]["points"] == wb.planner.cloud.shape[0]
    assert captures[-1]["voxels"] == client.get(f"/api/sessions/{sid}").json()["voxels"]
    camera = settings.devices.camera
    for c in captures:
        frame = load_frame(settings.data_dir / "sessions" / sid / c["frame"], c["frame_sha256"])
        assert frame.depth.shape == (camera.height, camera.width) and set(c["pose"]) == {"position", "wxyz"}
    plans = [e for e in events if e["kind"] == "plan"]
    assert plans[0]["plan_id"] == plan["plan_id"] and plans[0]["best"]["index"] == plan["best"]["index"]
    assert plans[0]["best"]["score"] == plan["best"]["score"] and plans[0]["timings"]["score"] > 0
    decisions = [e for e in events if e["kind"] == "decision"]
    assert [(d["decision"], d["index"]) for d in decisions] == [
        ("override", other),
        ("step", plans[1]["best"]["index"]),
    ]
    assert all(d["time"] >= plans[0]["time"] for d in decisions)
    assert (
        events[5]["changes"] == {"termination": {"max_views": 6}}
        and events[5]["config"]["termination"]["max_views"] == 6
    )
    error = events[8]
    assert "capture failed" in error["message"] and error["restored_plan"] == plans[1]["plan_id"]
    assert events[9] == {**events[9], "action": "step", "plan_id": plans[1]["plan_id"]}
    # the frame of the failed capture was never written
    frames = sorted(p.name for p in (settings.data_dir / "sessions" / sid / "frames").iterdir())
    assert frames == ["000001.npz", "000002.npz", "000003.npz"]
    assert client.delete(f"/api/sessions/{sid}").status_code == 204
    assert not (settings.data_dir / "sessions" / sid).exists()  # moved to the trash, marked deleted
    (trashed,) = (settings.data_dir / "sessions" / ".trash").iterdir()
    assert trashed.name.startswith(f"{sid}-")
    last = json.loads((trashed / JOURNAL_FILE).read_text().splitlines()[-1])
    assert last["kind"] == "deleted"


def test_an_unwritable_data_dir_refuses_new_sessions_clearly(settings: AppSettings) -> None:
    from apphelpers import BASE_URL

    from app.main import create_app

    settings.data_dir.parent.mkdir(parents=True, exist_ok=True)
    settings.data_dir.write_text("a file where the data directory should be")
    with TestClient(create_app(settings), base_url=BASE_URL) as client:
        r = client.post("/api/sessions", json={"config": SMALL})
        assert r.status_code == 503 and "cannot journal" in r.json()["detail"]
        assert client.get("/api/sessions").json() == []
