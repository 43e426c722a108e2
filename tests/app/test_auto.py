"""Auto mode stops at the first fault, and on the stop button after the action in flight."""

from __future__ import annotations

import threading
from typing import Any

from apphelpers import SMALL, registry_of
from fastapi.testclient import TestClient


def wait_until_not_auto(client: TestClient, sid: str, timeout: float = 60.0) -> dict[str, Any]:
    """Wait for the auto run's thread to end (a join, no polling); the status after it."""
    assert registry_of(client).get(sid).auto.join(timeout), "auto mode did not end"
    return client.get(f"/api/sessions/{sid}").json()


def test_auto_mode_stops_at_the_first_fault(client: TestClient) -> None:
    faults = {"schedule": [{"kind": "capture_failure", "at": 4}]}  # capture 1 is the first view: step 3 fails
    sid = client.post("/api/sessions", json={"config": SMALL, "faults": faults}).json()["id"]
    client.post(f"/api/sessions/{sid}/capture")
    assert client.post(f"/api/sessions/{sid}/auto", json={"count": 10}).status_code == 202
    st = wait_until_not_auto(client, sid)
    assert (st["state"], st["iteration"], st["moves"]) == ("error", 3, 4)
    assert "capture failed" in st["error"] and st["retry"] == "auto"
    # the run's thread has ended (joined above): nothing can happen after the fault
    doc = client.get(f"/api/sessions/{sid}/export").json()
    assert len(doc["plans"]) == 3 and [d["kind"] for d in doc["decisions"]] == ["auto"] * 3
    assert doc["session"]["iteration"] == 3 and doc["session"]["moves"] == 4
    assert st["pending_plan"]["plan_id"] == doc["plans"][-1]["plan_id"]  # the failed step's plan is pending again
    st = client.post(f"/api/sessions/{sid}/retry").json()
    assert (st["state"], st["iteration"]) == ("ready", 4)


def test_the_stop_button_ends_auto_mode_after_the_action_in_flight(client: TestClient, new_session) -> None:
    sid = new_session(client)
    client.post(f"/api/sessions/{sid}/capture")
    wb = registry_of(client).get(sid)
    real_move = wb.cell.move_to
    second_move = threading.Event()
    release = threading.Event()
    calls = []

    def move(pose):
        calls.append(pose)
        if len(calls) == 2:  # step 1 passes, step 2 waits here
            second_move.set()
            assert release.wait(30)
        return real_move(pose)

    wb.cell.move_to = move
    assert client.post(f"/api/sessions/{sid}/auto", json={"count": 10}).status_code == 202
    assert second_move.wait(30)
    r = client.post(f"/api/sessions/{sid}/stop")
    assert r.status_code == 200 and r.json()["state"] == "auto"  # the move in flight is not cut off
    release.set()
    st = wait_until_not_auto(client, sid)
    assert (st["state"], st["iteration"], st["moves"], st["error"]) == ("ready", 3, 3, None)
    st = client.get(f"/api/sessions/{sid}").json()
    assert (st["iteration"], st["moves"]) == (3, 3) and len(calls) == 2
    doc = client.get(f"/api/sessions/{sid}/export").json()
    assert len(doc["plans"]) == 2 and [d["kind"] for d in doc["decisions"]] == ["auto", "auto"]
    assert [e["kind"] for e in doc["events"]] == ["auto_start", "auto_stop"]
    assert client.post(f"/api/sessions/{sid}/stop").json()["state"] == "ready"  # stopping again: no-op
