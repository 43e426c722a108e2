"""Journals degrade, never vanish: a damaged journal is listed as ``damaged`` with the reason, and resume
recovers everything up to the last good record and frame and says what was dropped."""

from __future__ import annotations

import json
from typing import Any

import numpy as np
import pytest
from apphelpers import BASE_URL, SMALL
from fastapi.testclient import TestClient

from app.main import create_app
from app.settings import AppSettings
from workbench.journal.store import JOURNAL_FILE


def three_views(settings: AppSettings) -> tuple[str, list[dict[str, Any]]]:
    """A journaled session with three captures and a pending plan; (id, its status after each capture)."""
    with TestClient(create_app(settings), base_url=BASE_URL) as client:
        sid = client.post("/api/sessions", json={"config": SMALL, "seed": 3}).json()["id"]
        states = [client.post(f"/api/sessions/{sid}/capture").json()]
        for _ in range(2):
            plan = client.post(f"/api/sessions/{sid}/plan").json()
            body = {"plan_id": plan["plan_id"], "index": plan["best"]["index"]}
            assert client.post(f"/api/sessions/{sid}/approve", json=body).status_code == 200
            states.append(client.get(f"/api/sessions/{sid}").json())
        client.post(f"/api/sessions/{sid}/plan")
    return sid, states


def lines_of(settings: AppSettings, sid: str) -> list[str]:
    return (settings.data_dir / "sessions" / sid / JOURNAL_FILE).read_text().splitlines()


def test_garbage_in_the_middle_lists_damaged_and_resumes_up_to_it(settings: AppSettings) -> None:
    sid, states = three_views(settings)
    path = settings.data_dir / "sessions" / sid / JOURNAL_FILE
    lines = lines_of(settings, sid)
    third = max(i for i, line in enumerate(lines) if json.loads(line)["kind"] == "capture")
    original = path.read_bytes()
    damaged = [*lines[:third], "\x00\x17 this is not json {", *lines[third:]]
    path.write_text("\n".join(damaged) + "\n")
    with TestClient(create_app(settings), base_url=BASE_URL) as client:
        (listed,) = client.get("/api/sessions").json()
        assert listed["id"] == sid and listed["state"] == "damaged"
        assert f"line {third + 1} is damaged" in listed["error"] and listed["iteration"] == 2
        assert client.get(f"/api/sessions/{sid}").json()["state"] == "damaged"
        r = client.post(f"/api/sessions/{sid}/resume")
        assert r.status_code == 200, r.text
        body = r.json()
        assert body["dropped"] and f"line {third + 1} is damaged" in body["dropped"][0]
        st = body["session"]
        assert (st["iteration"], st["points"], st["voxels"]) == (2, states[1]["points"], states[1]["voxels"])
        # it goes on from there: plan, approve, a third view
        plan = client.post(f"/api/sessions/{sid}/plan").json()
        body = {"plan_id": plan["plan_id"], "index": plan["best"]["index"]}
        assert client.post(f"/api/sessions/{sid}/approve", json=body).json()["iteration"] == 3
    kept = sorted((settings.data_dir / "sessions" / sid).glob("journal.damaged-*.jsonl"))
    assert len(kept) == 1 and kept[0].read_text() == "\n".join(damaged) + "\n"  # the whole file, kept aside
    assert original != path.read_bytes()


@pytest.mark.slow
def test_a_damaged_frame_resumes_up_to_the_view_before_it(settings: AppSettings) -> None:
    sid, states = three_views(settings)
    frame = settings.data_dir / "sessions" / sid / "frames" / "000003.npz"
    data = dict(np.load(frame))
    data["depth"][10, 10] += 1.0
    np.savez(frame, **data)
    with TestClient(create_app(settings), base_url=BASE_URL) as client:
        assert client.get(f"/api/sessions/{sid}").json()["state"] == "interrupted"  # the lines are intact
        r = client.post(f"/api/sessions/{sid}/resume")
        assert r.status_code == 200, r.text
        dropped = r.json()["dropped"]
        assert len(dropped) == 1 and "(capture)" in dropped[0] and "checksum mismatch" in dropped[0]
        st = r.json()["session"]
        assert (st["iteration"], st["points"]) == (2, states[1]["points"])
    # the resumed journal reads back clean; the whole original is kept aside
    with TestClient(create_app(settings), base_url=BASE_URL) as client:
        assert client.get(f"/api/sessions/{sid}").json()["state"] == "interrupted"
        r = client.post(f"/api/sessions/{sid}/resume")
        assert r.status_code == 200 and r.json()["dropped"] == [] and r.json()["session"]["iteration"] == 2
    assert len(list((settings.data_dir / "sessions" / sid).glob("journal.damaged-*.jsonl"))) == 1


def test_an_unreadable_journal_is_listed_not_hidden(settings: AppSettings) -> None:
    directory = settings.data_dir / "sessions" / "0badf00d"
    directory.mkdir(parents=True)
    (directory / JOURNAL_FILE).write_text("garbage\nmore garbage\n")
    with TestClient(create_app(settings), base_url=BASE_URL) as client:
        (listed,) = client.get("/api/sessions").json()
        assert listed["id"] == "0badf00d" and listed["state"] == "damaged" and "unreadable" in listed["error"]
        r = client.post("/api/sessions/0badf00d/resume")
        assert r.status_code == 422 and "cannot resume" in r.json()["detail"]
        assert client.delete("/api/sessions/0badf00d").status_code == 204  # it can still be thrown away
        assert client.get("/api/sessions").json() == []
    assert not directory.exists()


def test_a_session_with_an_intact_journal_resumes_with_nothing_dropped(settings: AppSettings) -> None:
    sid, states = three_views(settings)
    with TestClient(create_app(settings), base_url=BASE_URL) as client:
        r = client.post(f"/api/sessions/{sid}/resume").json()
        assert r["dropped"] == [] and r["verified"] and r["session"]["iteration"] == 3
        assert r["session"]["points"] == states[2]["points"]
    assert not list((settings.data_dir / "sessions" / sid).glob("journal.damaged-*"))
