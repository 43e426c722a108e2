"""Commands that move hardware take strict types (no bool or string for a number), and anything unexpected is a
JSON 500 whose error id is in the log, never text/plain."""

from __future__ import annotations

import json
import logging

import pytest
from apphelpers import BASE_URL, registry_of
from fastapi.testclient import TestClient

from app.main import create_app
from app.settings import AppSettings


def send(client: TestClient, method: str, path: str, body: object):
    return client.request(method, path, content=json.dumps(body), headers={"content-type": "application/json"})


LOOSE_INDICES = [True, False, "1", "0", 1.0, 1.5, None, [1], {"i": 1}]
LOOSE_POSITIONS = [[True, 0, 0.3], ["1", 0, 0.3], [0, None, 0.3], [0, 0, "0.3"], [0, 0, [0.3]]]


def test_loose_types_never_move_the_arm(client: TestClient, planned_session) -> None:
    sid, plan = planned_session(client)
    base = f"/api/sessions/{sid}"
    before = client.get(base).json()
    for index in LOOSE_INDICES:
        r = send(client, "POST", f"{base}/approve", {"plan_id": plan["plan_id"], "index": index})
        assert r.status_code == 422, (index, r.text)
        r = send(client, "PUT", f"{base}/selection", {"index": index})
        assert r.status_code == 422, (index, r.text)
    for position in LOOSE_POSITIONS:
        pose = {"position": position, "wxyz": [0, 1, 0, 0]}
        r = send(client, "POST", f"{base}/approve", {"plan_id": plan["plan_id"], "pose": pose})
        assert r.status_code == 422, (position, r.text)
        r = send(client, "PUT", f"{base}/custom_pose", {"pose": pose})
        assert r.status_code == 422, (position, r.text)
        r = send(client, "PUT", f"{base}/custom_pose", {"pose": {"position": [0, 0, 0.3], "wxyz": [True, 0, 0, 0]}})
        assert r.status_code == 422, r.text
    for count in (True, "2", 2.0):
        assert send(client, "POST", f"{base}/step", {"count": count}).status_code == 422
        assert send(client, "POST", f"{base}/auto", {"count": count}).status_code == 422
    assert send(client, "POST", "/api/sessions", {"seed": True}).status_code == 422
    after = client.get(base).json()
    assert after["moves"] == before["moves"] == 1 and after["selected"] == before["selected"]
    assert after["pending_plan"]["plan_id"] == plan["plan_id"] and after["custom_pose"] is None
    # the same commands with honest types still work: integers are numbers, the index an integer
    pose = {"position": [0, 0, 1], "wxyz": [0, 1, 0, 0]}
    assert send(client, "PUT", f"{base}/custom_pose", {"pose": pose}).status_code == 200
    assert send(client, "PUT", f"{base}/selection", {"index": 1}).status_code == 200
    r = send(client, "POST", f"{base}/approve", {"plan_id": plan["plan_id"], "index": plan["best"]["index"]})
    assert r.status_code == 200 and client.get(base).json()["moves"] == 2


def test_an_unexpected_error_is_json_500_with_an_id_in_the_log(
    settings: AppSettings, caplog: pytest.LogCaptureFixture
) -> None:
    with TestClient(create_app(settings), base_url=BASE_URL, raise_server_exceptions=False) as client:
        registry = registry_of(client)

        def broken() -> list:
            raise ZeroDivisionError("a bug nobody foresaw")

        registry.list_status = broken
        with caplog.at_level(logging.ERROR, logger="app.main"):
            r = client.get("/api/sessions")
        assert r.status_code == 500 and r.headers["content-type"] == "application/json"
        error_id = r.json()["error_id"]
        assert len(error_id) == 12 and error_id in r.json()["detail"] and "bug nobody" not in r.json()["detail"]
        logged = [rec for rec in caplog.records if error_id in rec.getMessage()]
        assert logged and logged[0].exc_info is not None and "ZeroDivisionError" in logged[0].getMessage()
        assert client.get("/api/health").json() == {"status": "ok"}  # the server goes on
