"""A session's arm: the create request's ``arm`` (GET /api/arms lists them), the journal header records it with
the devices, a resume rebuilds the same arm, and a journal that names no preset (as written before presets) resumes
with the UR5."""

from __future__ import annotations

import json
from collections.abc import Iterator
from contextlib import contextmanager
from typing import Any

import pytest
from apphelpers import BASE_URL, SMALL
from fastapi.testclient import TestClient

from app.main import create_app
from app.settings import AppSettings
from devices.arm.presets import PRESETS
from workbench.journal.store import read_journal


@contextmanager
def server(settings: AppSettings) -> Iterator[TestClient]:
    with TestClient(create_app(settings), base_url=BASE_URL) as c:
        yield c


def create(client: TestClient, **body: Any) -> str:
    r = client.post("/api/sessions", json={"config": SMALL, "seed": 3, **body})
    assert r.status_code == 201, r.text
    return r.json()["id"]


def joints(client: TestClient, sid: str) -> list[float]:
    """The session's arm joints as the cell reports them."""
    session = client.app.state.registry.get(sid)  # type: ignore[attr-defined]
    return [float(v) for v in session.cell.reach.joint_positions()]


def test_the_arms_are_listed_with_the_default_first(client: TestClient) -> None:
    arms = client.get("/api/arms").json()["arms"]
    assert [a["name"] for a in arms] == [*PRESETS, "reach_sphere"]
    assert [a["name"] for a in arms if a["default"]] == ["ur5"]
    assert {a["name"]: a["dof"] for a in arms}["panda"] == 7


def test_an_unknown_arm_is_refused_and_nothing_is_created(client: TestClient) -> None:
    before = client.get("/api/sessions").json()
    r = client.post("/api/sessions", json={"config": SMALL, "arm": "/etc/robot.urdf"})
    assert r.status_code == 422 and "panda" in r.json()["detail"]
    assert client.get("/api/sessions").json() == before


@pytest.mark.slow
def test_a_panda_session_journals_its_arm_and_resumes_with_it(settings: AppSettings) -> None:
    with server(settings) as a:
        sid = create(a, arm="panda")
        assert a.post(f"/api/sessions/{sid}/capture").status_code == 200
        assert len(joints(a, sid)) == 7  # the fingers are locked, not joints of the arm
    header = read_journal(settings.data_dir / "sessions" / sid).header
    assert header["devices"]["cell"]["arm"]["urdf"] == "panda"
    with server(settings) as b:
        r = b.post(f"/api/sessions/{sid}/resume")
        assert r.status_code == 200, r.text
        assert len(joints(b, sid)) == 7


def test_a_journal_without_the_arm_fields_resumes_as_the_ur5(settings: AppSettings) -> None:
    with server(settings) as a:
        sid = create(a)
        a.post(f"/api/sessions/{sid}/capture")
    path = settings.data_dir / "sessions" / sid / "journal.jsonl"
    lines = path.read_text().splitlines()
    header = json.loads(lines[0])
    arm = header["devices"]["cell"]["arm"]
    for key in ("locked_joints", "locked_positions"):
        del arm[key]  # as an older build wrote it: explicit UR5 mount, home and flange
    arm.update(base=[-0.85, 0.0, 0.0], home_deg=[0.0, -90.0, 90.0, -90.0, -90.0, 0.0], flange_frame="tool0")
    lines[0] = json.dumps(header)
    path.write_text("\n".join(lines) + "\n")
    with server(settings) as b:
        r = b.post(f"/api/sessions/{sid}/resume")
        assert r.status_code == 200, r.text
        assert len(joints(b, sid)) == 6
