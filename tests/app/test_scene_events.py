"""The page's pushed events (``/api/events``): the status after every change, the session list, auth."""

from __future__ import annotations

from typing import Any

import pytest
from apphelpers import BASE_URL
from fastapi.testclient import TestClient
from starlette.websockets import WebSocketDisconnect

from app.main import create_app
from app.settings import AppSettings


def _until(ws: Any, predicate: Any, limit: int = 50) -> list[dict[str, Any]]:
    """Messages received until one satisfies ``predicate`` (that one last)."""
    seen = []
    for _ in range(limit):
        m = ws.receive_json()
        seen.append(m)
        if predicate(m):
            return seen
    raise AssertionError(f"no matching message in {seen}")


def test_status_is_pushed_after_every_change(client: TestClient, new_session) -> None:
    sid = new_session(client)
    with client.websocket_connect(f"/api/events?session={sid}") as ws:
        first = ws.receive_json()
        assert first["type"] == "status" and first["status"]["id"] == sid and first["status"]["state"] == "new"
        assert client.post(f"/api/sessions/{sid}/capture").status_code == 200
        seen = _until(ws, lambda m: m.get("event") == "captured")
        assert seen[0]["status"]["state"] == "capturing"
        assert seen[-1]["status"]["iteration"] == 1 and seen[-1]["status"]["state"] == "ready"
        plan = client.post(f"/api/sessions/{sid}/plan").json()
        seen = _until(ws, lambda m: m.get("event") == "planned")
        assert seen[-1]["status"]["pending_plan"]["plan_id"] == plan["plan_id"]
        k = (plan["best"]["index"] + 1) % 60
        client.put(f"/api/sessions/{sid}/selection", json={"index": k})
        assert _until(ws, lambda m: m.get("event") == "selection")[-1]["status"]["selected"] == k
        other = new_session(client)
        assert _until(ws, lambda m: m["type"] == "sessions") == [{"type": "sessions", "change": "created", "id": other}]
        client.delete(f"/api/sessions/{sid}")
        seen = _until(ws, lambda m: m["type"] == "deleted")
        assert {"type": "sessions", "change": "deleted", "id": sid} in seen


def test_an_unknown_session_is_closed_with_4404(client: TestClient) -> None:
    with client.websocket_connect("/api/events?session=nope") as ws:
        assert "nope" in ws.receive_json()["detail"]
        with pytest.raises(WebSocketDisconnect) as exc:
            ws.receive_json()
        assert exc.value.code == 4404


def test_a_foreign_origin_is_refused(client: TestClient) -> None:
    with (
        pytest.raises(WebSocketDisconnect) as exc,
        client.websocket_connect("/api/events", headers={"Origin": "http://evil.example"}) as ws,
    ):
        ws.receive_json()
    assert exc.value.code == 4403


def test_with_a_token_the_stream_needs_it(settings: AppSettings) -> None:
    token = "s" * 32
    with TestClient(create_app(settings.replace(token=token)), base_url=BASE_URL) as c:
        with pytest.raises(WebSocketDisconnect) as exc, c.websocket_connect("/api/events") as ws:
            ws.receive_json()
        assert exc.value.code == 4401
        sid = c.post("/api/sessions", json={}, headers={"Authorization": f"Bearer {token}"}).json()["id"]
        with c.websocket_connect(f"/api/events?session={sid}&token={token}") as ws:
            assert ws.receive_json()["status"]["id"] == sid
