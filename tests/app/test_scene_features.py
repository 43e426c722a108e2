"""What the page offers beyond the loop: a planner per session, delete into the trash, discard the last view."""

from __future__ import annotations

from pathlib import Path

import numpy as np
from apphelpers import BASE_URL, SMALL
from fastapi.testclient import TestClient

from app.main import create_app
from app.settings import AppSettings
from workbench.journal.discard import last_capture, without_discarded
from workbench.journal.store import read_journal, sessions_dir
from workbench.journal.trash import trash_dir


def test_the_planner_is_chosen_per_session_and_journaled(client: TestClient, settings: AppSettings) -> None:
    names = client.get("/api/planners").json()
    assert "projection" in names and "random" in names
    r = client.post("/api/sessions", json={"config": SMALL, "planner": "random"})
    assert r.status_code == 201
    sid = r.json()["id"]
    assert client.get(f"/api/sessions/{sid}").json()["planner"] == "random"
    assert read_journal(sessions_dir(settings.data_dir) / sid).header["planner"] == "random"
    bad = client.post("/api/sessions", json={"config": SMALL, "planner": "telepathy"})
    assert bad.status_code == 422 and "telepathy" in bad.json()["detail"] and "projection" in bad.json()["detail"]
    # the random planner's choice differs from the projection planner's on the same scan
    ref = client.post("/api/sessions", json={"config": SMALL}).json()["id"]
    for s in (sid, ref):
        client.post(f"/api/sessions/{s}/capture")
    scores = {s: client.post(f"/api/sessions/{s}/plan").json()["best"]["score"] for s in (sid, ref)}
    assert scores[sid] != scores[ref]


def test_delete_moves_the_journal_to_the_trash_until_restart(settings: AppSettings, new_session) -> None:
    with TestClient(create_app(settings), base_url=BASE_URL) as c:
        sid = new_session(c)
        assert (sessions_dir(settings.data_dir) / sid).is_dir()
        assert c.delete(f"/api/sessions/{sid}").status_code == 204
        assert not (sessions_dir(settings.data_dir) / sid).exists()
        kept = list(trash_dir(settings.data_dir).iterdir())
        assert [p.name.split("-")[0] for p in kept] == [sid]
        assert read_journal(kept[0]).deleted
        assert c.get(f"/api/sessions/{sid}").status_code == 404
    with TestClient(create_app(settings), base_url=BASE_URL) as c:  # a restart empties the trash
        assert list(trash_dir(settings.data_dir).iterdir()) == []
        assert c.get("/api/sessions").json() == []


def test_discard_last_view_rebuilds_without_it(client: TestClient, planned_session, settings: AppSettings) -> None:
    sid, plan = planned_session(client)
    before = client.get(f"/api/sessions/{sid}").json()
    wb = client.app.state.registry.get(sid)  # type: ignore[attr-defined]
    cloud_1 = wb.planner.cloud.copy()
    body = {"plan_id": plan["plan_id"], "index": plan["best"]["index"]}
    assert client.post(f"/api/sessions/{sid}/approve", json=body).status_code == 200
    assert client.get(f"/api/sessions/{sid}").json()["iteration"] == 2
    r = client.post(f"/api/sessions/{sid}/discard")
    assert r.status_code == 200, r.text
    out = r.json()
    assert out["discarded"] == 2 and out["mismatches"] == []
    st = out["session"]
    assert st["iteration"] == 1 and st["points"] == before["points"] and st["voxels"] == before["voxels"]
    # the plan whose approval took the discarded view is pending again: approve another candidate, or plan again
    assert st["state"] == "planned" and st["pending_plan"]["plan_id"] == plan["plan_id"]
    assert np.array_equal(wb.planner.cloud, cloud_1)
    # journaled; a plan again gives the same plan as before the discarded view
    events = read_journal(Path(wb.journal.directory)).events
    assert [e["kind"] for e in events if e["kind"] == "discard"] == ["discard"]
    last = last_capture(events)
    assert last is not None and last["iteration"] == 1
    # ... the same plan as a twin session (same model and seed) that never took the discarded view plans again:
    # a plan's fits are warm-started from the last plan's (workbench/journal/rebuild.py), so "again" is compared
    # with "again", not with the first plan (at another camera resolution their scores differ: 292 against 89)
    twin, twin_plan = planned_session(client)
    assert twin_plan["best"] == plan["best"]
    again = client.post(f"/api/sessions/{twin}/plan").json()["best"]
    assert client.post(f"/api/sessions/{sid}/plan").json()["best"] == again
    # discard down to nothing, then nothing more to discard
    assert client.post(f"/api/sessions/{sid}/discard").json()["session"]["state"] == "new"
    assert client.post(f"/api/sessions/{sid}/discard").status_code == 409


def test_without_discarded_keeps_config_changes() -> None:
    events = [
        {"seq": 1, "kind": "capture"}, {"seq": 2, "kind": "plan"}, {"seq": 3, "kind": "decision"},
        {"seq": 4, "kind": "capture"}, {"seq": 5, "kind": "config"}, {"seq": 6, "kind": "plan"},
        {"seq": 7, "kind": "discard", "capture_seq": 4},
    ]  # fmt: skip
    assert [e["seq"] for e in without_discarded(events)] == [1, 2, 3, 5, 7]
