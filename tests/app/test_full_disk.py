"""A full disk (ENOSPC at the journal's write boundary, tests/full_disk.py): every refused step says "disk full"
and how much is needed, leaves no debris (no ``.part`` frame, no empty journal) and acknowledges nothing a
restart would not bring back."""

from __future__ import annotations

from pathlib import Path

from apphelpers import BASE_URL, SMALL
from fastapi.testclient import TestClient

from app.main import create_app
from app.settings import AppSettings
from tests.full_disk import FullDisk


def _debris(data_dir: Path) -> list[str]:
    return sorted(str(p.relative_to(data_dir)) for p in (data_dir / "sessions").glob("*/frames/.*"))


def test_a_full_disk_refuses_a_view_clearly_and_leaves_no_part_file(settings: AppSettings) -> None:
    disk = FullDisk()
    with TestClient(create_app(settings), base_url=BASE_URL) as client, disk.installed():
        sid = client.post("/api/sessions", json={"config": SMALL}).json()["id"]
        disk.full = True
        r = client.post(f"/api/sessions/{sid}/capture")
        assert r.status_code == 503, r.text
        detail = r.json()["detail"]
        assert "disk full" in detail and "MB needed" in detail, detail
        assert _debris(settings.data_dir) == []
        status = client.get(f"/api/sessions/{sid}").json()
        assert (status["state"], status["iteration"]) == ("error", 0)
        disk.full = False
        r = client.post(f"/api/sessions/{sid}/retry")  # the same step again, now that there is room
        assert (r.status_code, r.json()["iteration"]) == (200, 1), r.text


def test_a_create_on_a_full_disk_leaves_nothing_behind(settings: AppSettings) -> None:
    disk = FullDisk()
    with TestClient(create_app(settings), base_url=BASE_URL) as client, disk.installed():
        disk.full = True
        r = client.post("/api/sessions", json={"config": SMALL})
        assert r.status_code == 503 and "disk full" in r.json()["detail"], r.text
        assert client.get("/api/sessions").json() == []
    assert list((settings.data_dir / "sessions").iterdir()) == []
    with TestClient(create_app(settings), base_url=BASE_URL) as client:  # no empty journal listed as damaged
        assert client.get("/api/sessions").json() == []


def test_a_full_disk_after_a_resume_is_an_error_not_a_200(settings: AppSettings) -> None:
    with TestClient(create_app(settings), base_url=BASE_URL) as a:
        sid = a.post("/api/sessions", json={"model": "mug", "config": SMALL}).json()["id"]
        assert a.post(f"/api/sessions/{sid}/capture").status_code == 200
    disk = FullDisk()
    with TestClient(create_app(settings), base_url=BASE_URL) as b, disk.installed():
        assert b.post(f"/api/sessions/{sid}/resume").status_code == 200
        disk.full = True
        r = b.post(f"/api/sessions/{sid}/step")
        assert r.status_code == 503 and "disk full" in r.json()["detail"], r.text
        assert b.get(f"/api/sessions/{sid}").json()["iteration"] == 1
        disk.full = False
        r = b.post(f"/api/sessions/{sid}/retry")  # the failed step again, now that there is room
        assert (r.status_code, r.json()["iteration"]) == (200, 2), r.text
    with TestClient(create_app(settings), base_url=BASE_URL) as c:
        r = c.post(f"/api/sessions/{sid}/resume")
        assert (r.status_code, r.json()["dropped"]) == (200, []), r.text
        assert c.get(f"/api/sessions/{sid}").json()["iteration"] == 2
