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

    def move(pose, plate_angle=None, then=(), motion=None, capture_hz=0.0, on_frame=None):  # Cell.move_to's arguments
        calls.append(pose)
        if len(calls) == 2:  # step 1 passes, step 2 waits here
            second_move.set()
            assert release.wait(30)
        return real_move(pose, plate_angle, then, motion, capture_hz=capture_hz, on_frame=on_frame)

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


def test_auto_mode_goes_on_past_a_refused_move_and_an_unusable_frame(client: TestClient) -> None:
    """The planner's choice refused at move time (arm action 2) or its frame unusable (capture 4): auto mode takes
    the plan's next eligible candidate each time and runs all its steps."""
    faults = {"schedule": [{"kind": "move_refused", "at": 2}, {"kind": "empty_frame", "at": 4}]}
    config = {**SMALL, "termination": {"max_views": 30, "stop_without_frontier": False}}  # the rule never stops it
    sid = client.post("/api/sessions", json={"config": config, "faults": faults}).json()["id"]
    client.post(f"/api/sessions/{sid}/capture")
    assert client.post(f"/api/sessions/{sid}/auto", json={"count": 4}).status_code == 202
    st = wait_until_not_auto(client, sid)
    assert (st["state"], st["iteration"], st["error"]) == ("ready", 5, None)
    assert st["refused_moves"] == 2
    doc = client.get(f"/api/sessions/{sid}/export").json()
    assert [r["reason"] for r in doc["refusals"]] == ["refused", "frame_rejected"]
    for refusal in doc["refusals"]:  # each refusal names the candidate taken instead, decided in the same plan
        taken = [d["index"] for d in doc["decisions"] if d["plan_id"] == refusal["plan_id"]]
        assert taken == [refusal["candidate"], refusal["next"]] and refusal["next"] != refusal["candidate"]
    assert [e["kind"] for e in doc["events"]].count("refused") == 2
