"""Resume: a restarted server lists the journaled sessions and rebuilds the same map and the same next plan.

These tests restart the app in-process on the same data directory (the journal is all a restart sees; the
real ``kill -9`` of a server process is in test_kill9.py)."""

from __future__ import annotations

from collections.abc import Iterator
from contextlib import contextmanager
from typing import Any

import pytest
from apphelpers import BASE_URL, SMALL
from fastapi.testclient import TestClient

from app.main import create_app
from app.settings import AppSettings
from workbench.journal.store import JournalWriter, read_journal


@contextmanager
def server(settings: AppSettings) -> Iterator[TestClient]:
    with TestClient(create_app(settings), base_url=BASE_URL) as c:
        yield c


def state_of(client: TestClient, sid: str) -> dict[str, Any]:
    st = client.get(f"/api/sessions/{sid}").json()
    plan = st["pending_plan"]
    cands = client.get(f"/api/sessions/{sid}/candidates").json() if plan else None
    return {
        "iteration": st["iteration"],
        "points": st["points"],
        "voxels": st["voxels"],
        "coverage": st["coverage"],
        "plan_id": plan and plan["plan_id"],
        "best": plan and plan["best"],
        "scores": cands and [(c["index"], c["score"], c["eligible"]) for c in cands],
        "cloud": client.get(f"/api/sessions/{sid}/cloud.ply").content,
    }


def scan(client: TestClient, seed: int = 5) -> tuple[str, dict[str, Any]]:
    """A session two views in, with a pending plan."""
    sid = client.post("/api/sessions", json={"config": SMALL, "seed": seed}).json()["id"]
    client.post(f"/api/sessions/{sid}/capture")
    plan = client.post(f"/api/sessions/{sid}/plan").json()
    client.post(f"/api/sessions/{sid}/approve", json={"plan_id": plan["plan_id"], "index": plan["best"]["index"]})
    assert client.post(f"/api/sessions/{sid}/step").json()["iteration"] == 3
    return sid, client.post(f"/api/sessions/{sid}/plan").json()


@pytest.mark.slow
def test_resume_rebuilds_the_same_map_and_plan_and_continues_identically(settings: AppSettings) -> None:
    with server(settings) as a:
        sid, plan = scan(a)
        before = state_of(a, sid)
    with server(settings) as b:
        listed = b.get("/api/sessions").json()
        assert [(s["id"], s["state"], s["iteration"]) for s in listed] == [(sid, "interrupted", 3)]
        assert listed[0]["voxels"] == before["voxels"] and "resume" in listed[0]["error"]
        r = b.post(f"/api/sessions/{sid}/plan")
        assert r.status_code == 409 and "resume" in r.json()["detail"]
        r = b.post(f"/api/sessions/{sid}/resume")
        assert r.status_code == 200, r.text
        assert (r.json()["verified"], r.json()["mismatches"], r.json()["interrupted"]) == (True, [], None)
        after = state_of(b, sid)
        assert after == before  # same voxels, cloud, points, coverage, pending plan_id, best, every score
        assert b.post(f"/api/sessions/{sid}/resume").status_code == 409  # already live
        # it goes on exactly as an uninterrupted session with the same seed does
        control, control_plan = scan(b)
        assert control_plan["best"] == plan["best"]
        for s, p in ((sid, plan), (control, control_plan)):
            body = {"plan_id": p["plan_id"], "index": p["best"]["index"]}
            assert b.post(f"/api/sessions/{s}/approve", json=body).status_code == 200
        nxt = b.post(f"/api/sessions/{sid}/plan").json()
        ref = b.post(f"/api/sessions/{control}/plan").json()
        assert nxt["best"] == ref["best"]
        assert {k: v for k, v in state_of(b, sid).items() if k != "plan_id"} == {
            k: v for k, v in state_of(b, control).items() if k != "plan_id"
        }


def test_a_step_cut_by_the_crash_is_pending_again(settings: AppSettings) -> None:
    with server(settings) as a:
        sid, plan = scan(a)
        before = state_of(a, sid)
    # what a server killed between journaling the decision and capturing leaves behind
    journal = read_journal(settings.data_dir / "sessions" / sid)
    writer = JournalWriter.reopen(journal)
    writer.append("decision", decision="approve", plan_id=plan["plan_id"], index=plan["best"]["index"])
    writer.close()
    with server(settings) as b:
        r = b.post(f"/api/sessions/{sid}/resume").json()
        assert r["interrupted"] == plan["plan_id"] and r["verified"]
        assert state_of(b, sid) == before
        body = {"plan_id": plan["plan_id"], "index": plan["best"]["index"]}
        assert b.post(f"/api/sessions/{sid}/approve", json=body).json()["iteration"] == 4


def test_resume_after_a_fault_and_after_a_config_change(settings: AppSettings) -> None:
    with server(settings) as a:
        faults = {"schedule": [{"kind": "turntable_error", "at": 2}]}
        sid = a.post("/api/sessions", json={"config": SMALL, "faults": faults}).json()["id"]
        a.post(f"/api/sessions/{sid}/capture")
        assert a.patch(f"/api/sessions/{sid}/config", json={"candidates": {"count": 40}}).status_code == 200
        plan = a.post(f"/api/sessions/{sid}/plan").json()
        assert plan["n_candidates"] == 40
        body = {"plan_id": plan["plan_id"], "index": plan["best"]["index"]}
        assert a.post(f"/api/sessions/{sid}/approve", json=body).status_code == 503
        before = state_of(a, sid)
    with server(settings) as b:
        r = b.post(f"/api/sessions/{sid}/resume").json()
        assert r["verified"] and r["session"]["pending_plan"]["n_candidates"] == 40
        assert state_of(b, sid) == before  # the restored plan of the failed approval is pending
        assert b.post(f"/api/sessions/{sid}/approve", json=body).json()["iteration"] == 2  # faults are not re-armed


def test_resume_and_delete_errors(settings: AppSettings) -> None:
    with server(settings) as a:
        keep = a.post("/api/sessions", json={"config": SMALL}).json()["id"]
        gone = a.post("/api/sessions", json={"config": SMALL}).json()["id"]
        a.post(f"/api/sessions/{keep}/capture")
    (settings.data_dir / "sessions" / "deadbeef").mkdir()
    (settings.data_dir / "sessions" / "deadbeef" / "journal.jsonl").write_text("not json\nat all\n")
    with server(settings) as b:
        assert b.post("/api/sessions/nope/resume").status_code == 404
        listed = {s["id"]: s["state"] for s in b.get("/api/sessions").json()}
        assert listed == {keep: "interrupted", gone: "interrupted", "deadbeef": "damaged"}  # listed, not hidden
        assert b.post("/api/sessions/deadbeef/resume").status_code == 422
        assert b.delete("/api/sessions/deadbeef").status_code == 204
        assert b.delete(f"/api/sessions/{gone}").status_code == 204
        assert b.get(f"/api/sessions/{gone}").status_code == 404
        assert b.post(f"/api/sessions/{keep}/resume").json()["session"]["state"] == "ready"
    with server(settings) as c:
        assert [s["id"] for s in c.get("/api/sessions").json()] == [keep]


@pytest.mark.parametrize("mode", ["sequence", "nearest"])
def test_a_journaled_session_replays_as_a_source(settings: AppSettings, mode: str) -> None:
    with server(settings) as a:
        sid, _ = scan(a)
        recorded = a.get(f"/api/sessions/{sid}/export").json()["iterations"]
    with server(settings) as b:
        body = {"config": SMALL, "seed": 5, "source": {"kind": "replay", "session": sid, "mode": mode}}
        r = b.post("/api/sessions", json=body)
        assert r.status_code == 201, r.text
        rid = r.json()["id"]
        st = b.post(f"/api/sessions/{rid}/capture").json()
        assert (st["model"], st["points"], st["iteration"]) == (f"replay:{sid}", recorded[0]["points"], 1)
        assert st["coverage"] == recorded[0]["coverage"]  # the original object is known: coverage works
        if mode == "sequence":  # the recorded views come back in order whatever is approved
            assert b.post(f"/api/sessions/{rid}/step", json={"count": 2}).json()["points"] == recorded[2]["points"]
            r = b.post(f"/api/sessions/{rid}/step")
            assert r.status_code == 503 and "all 3 recorded frames" in r.json()["detail"]
        bad = {"source": {"kind": "replay", "session": "0badc0de"}}
        assert b.post("/api/sessions", json=bad).status_code == 404


@pytest.mark.slow
def test_views_taken_after_a_resume_survive_the_next_restart(settings: AppSettings) -> None:
    """A resumed session journals its new views (its view step once held the journal of before the
    resume, None, and wrote no frame), so a second restart brings back all of them."""
    with server(settings) as a:
        sid = a.post("/api/sessions", json={"model": "mug", "config": SMALL, "seed": 3}).json()["id"]
        assert a.post(f"/api/sessions/{sid}/capture").status_code == 200
        for _ in range(2):
            assert a.post(f"/api/sessions/{sid}/step").status_code == 200
    with server(settings) as b:
        r = b.post(f"/api/sessions/{sid}/resume")
        assert r.status_code == 200 and r.json()["dropped"] == [], r.text
        for expected in (4, 5):
            r = b.post(f"/api/sessions/{sid}/step")
            assert (r.status_code, r.json()["iteration"]) == (200, expected), r.text
        before = state_of(b, sid)
    frames = sorted(p.name for p in (settings.data_dir / "sessions" / sid / "frames").iterdir())
    assert frames == [f"{i:06d}.npz" for i in range(1, 6)]
    with server(settings) as c:
        r = c.post(f"/api/sessions/{sid}/resume")
        assert r.status_code == 200, r.text
        assert (r.json()["dropped"], r.json()["mismatches"]) == ([], [])
        after = state_of(c, sid)
        assert after["iteration"] == 5 and after == before
