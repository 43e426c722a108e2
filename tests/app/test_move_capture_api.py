"""The create request's ``move_capture`` (frames per second taken while the cell moves): the session's cell takes it,
the journal header records it with the devices, and a bad rate is refused with nothing created."""

from __future__ import annotations

from apphelpers import SMALL
from fastapi.testclient import TestClient

from app.settings import AppSettings
from workbench.journal.store import read_journal
from workbench.sources.parts import session_devices


def test_a_session_asked_for_capture_during_moves_gets_it_and_journals_it(
    client: TestClient, settings: AppSettings
) -> None:
    r = client.post("/api/sessions", json={"config": SMALL, "move_capture": 2.5})
    assert r.status_code == 201, r.text
    sid = r.json()["id"]
    session = client.app.state.registry.get(sid)  # type: ignore[attr-defined]
    assert session.cell.config.move_capture_hz == 2.5
    header = read_journal(settings.data_dir / "sessions" / sid).header
    assert header["devices"]["cell"]["move_capture_hz"] == 2.5
    assert session_devices(settings, "l-block", 0).cell.move_capture_hz == 0.0  # not asked: the server's (off)


def test_a_bad_rate_is_refused_and_nothing_is_created(client: TestClient) -> None:
    before = client.get("/api/sessions").json()
    for bad in (-1, 61, "fast"):
        r = client.post("/api/sessions", json={"config": SMALL, "move_capture": bad})
        assert r.status_code == 422, r.text
    assert client.get("/api/sessions").json() == before
