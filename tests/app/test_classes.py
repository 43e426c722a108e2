"""Class mode over REST: a class's seats are sessions (guided follows the class), students join with the code,
the teacher pauses all and resets one, the board reads seats without waking them, a projector viewer only
watches, a class survives a restart, and bad input creates nothing."""

from __future__ import annotations

from collections.abc import Iterator
from typing import Any

import pytest
from apphelpers import BASE_URL, SMALL, registry_of
from fastapi.testclient import TestClient

from app.main import create_app
from app.settings import AppSettings


def _class(client: TestClient, seats: int = 2, **body: Any) -> dict[str, Any]:
    r = client.post("/api/classes", json={"seats": seats, "config": SMALL, **body})
    assert r.status_code == 201, r.text
    return r.json()


@pytest.fixture
def quick(settings: AppSettings) -> AppSettings:
    """No worker processes: the seats' actions run in the server (these tests are about the class, not the work)."""
    return settings.replace(workers=False)


@pytest.fixture
def client(quick: AppSettings) -> Iterator[TestClient]:
    with TestClient(create_app(quick), base_url=BASE_URL) as c:
        yield c


def test_a_class_is_seats_of_guided_sessions_that_students_join_by_code(client: TestClient) -> None:
    made = _class(client, 3, model=["l-block", "mug"], guided=True)
    assert len(made["code"]) == 6 and made["join"] == f"/join/{made['code']}"
    assert [s["model"] for s in made["seats"]] == ["l-block", "mug", "l-block"]
    for seat in made["seats"]:  # every seat is an ordinary session, in guided mode
        status = client.get(f"/api/sessions/{seat['session']}").json()
        assert status["guided"] is True and status["model"] == seat["model"] and status["state"] == "new"
    assert {s["id"] for s in client.get("/api/sessions").json()} == {s["session"] for s in made["seats"]}

    first = client.post("/api/classes/join", json={"code": made["code"].lower()}).json()  # case does not matter
    second = client.post("/api/classes/join", json={"code": made["code"]}).json()
    assert (first["seat"], second["seat"]) == (1, 2)
    assert first["session"] == made["seats"][0]["session"] and first["url"] == f"/?session={first['session']}"
    client.post("/api/classes/join", json={"code": made["code"]})
    full = client.post("/api/classes/join", json={"code": made["code"]})
    assert full.status_code == 409 and "all 3 seats are taken" in full.json()["detail"]
    again = client.post("/api/classes/join", json={"code": made["code"], "seat": 2}).json()
    assert again["session"] == second["session"]  # a student comes back to their seat
    assert client.post("/api/classes/join", json={"code": "ZZZZZZ"}).status_code == 404

    sid = first["session"]
    assert client.post(f"/api/sessions/{sid}/capture").status_code == 200
    board = client.get(f"/api/classes/{made['id']}").json()
    one = board["seats"][0]
    assert (one["state"], one["views"], one["joined"], one["picture"]) == ("ready", 1, True, True)
    assert 0 < one["coverage"] < 1 and one["points"] > 0
    assert board["seats"][1]["picture"] is False and board["live"] == 3
    picture = client.get(f"/api/classes/{made['id']}/seats/1/picture.png")
    assert picture.status_code == 200 and picture.content[:8] == b"\x89PNG\r\n\x1a\n"
    assert client.get(f"/api/classes/{made['id']}/seats/2/picture.png").status_code == 404
    qr = client.get(f"/api/classes/{made['id']}/qr.svg")
    assert qr.status_code == 200 and qr.text.lstrip().startswith("<?xml") and "<svg" in qr.text
    assert client.get("/board").status_code == 200 and client.get(f"/join/{made['code']}").status_code == 200


def test_pause_all_refuses_changes_and_reset_gives_a_seat_a_new_session(client: TestClient) -> None:
    made = _class(client, 2)
    cid, a, b = made["id"], made["seats"][0]["session"], made["seats"][1]["session"]
    assert client.post(f"/api/sessions/{a}/capture").status_code == 200
    paused = client.post(f"/api/classes/{cid}/pause", json={"paused": True}).json()
    assert paused["paused"] is True
    refused = client.post(f"/api/sessions/{b}/capture")
    assert refused.status_code == 409 and "paused the class" in refused.json()["detail"]
    assert client.get(f"/api/sessions/{b}").json()["iteration"] == 0  # nothing ran
    assert client.get(f"/api/sessions/{a}/cloud.ply").status_code == 200  # reads still answer
    assert client.post(f"/api/classes/{cid}/pause", json={"paused": False}).json()["paused"] is False
    assert client.post(f"/api/sessions/{b}/capture").status_code == 200

    reset = client.post(f"/api/classes/{cid}/seats/1/reset").json()
    fresh = reset["seats"][0]
    assert fresh["session"] not in (a, b) and fresh["resets"] == 1
    assert client.get(f"/api/sessions/{a}").status_code == 404  # the old scan is gone
    assert client.get(f"/api/sessions/{fresh['session']}").json()["iteration"] == 0
    assert reset["seats"][1]["session"] == b  # the other seat is untouched
    assert client.post(f"/api/classes/{cid}/seats/3/reset").status_code == 404


@pytest.mark.parametrize(
    "body",
    [
        {"seats": 0},
        {"seats": 10_000},
        {"seats": 2, "model": "no-such-object"},
        {"seats": 2, "model": ["l-block", "no-such-object"]},
        {"seats": 2, "planner": "no-such-planner"},
        {"seats": 2, "config": {"voxel": {"resolution": -1}}},
        {"seats": True},
        {"seats": 2, "guided": "yes"},
    ],
)
def test_bad_input_is_422_and_creates_nothing(client: TestClient, quick: AppSettings, body: dict[str, Any]) -> None:
    r = client.post("/api/classes", json=body)
    assert r.status_code == 422, r.text
    assert client.get("/api/classes").json() == [] and client.get("/api/sessions").json() == []
    assert not list((quick.data_dir / "classes").glob("*.json")) if (quick.data_dir / "classes").exists() else True


def test_the_live_limit_follows_the_class_and_the_board_wakes_no_seat(quick: AppSettings) -> None:
    with TestClient(create_app(quick.replace(max_live_sessions=2, max_class_seats=4)), base_url=BASE_URL) as c:
        too_many = c.post("/api/classes", json={"seats": 5})
        assert too_many.status_code == 422 and "max_class_seats" in too_many.json()["detail"]
        made = _class(c, 4)
        registry = registry_of(c)
        assert registry.live_limit() == 4 and len(registry.list()) == 4  # all four seats live past the limit of 2
        sid = made["seats"][3]["session"]
        assert registry.sleep(sid)
        board = c.get(f"/api/classes/{made['id']}").json()
        assert board["seats"][3]["asleep"] is True and board["seats"][3]["state"] == "asleep"
        assert board["live"] == 3 and sid not in {s.id for s in registry.list()}  # reading the board woke nothing
        assert c.post(f"/api/sessions/{sid}/capture").status_code == 200  # the student's next action wakes it
        assert c.get(f"/api/classes/{made['id']}").json()["seats"][3]["views"] == 1


def test_a_class_and_guided_survive_a_restart(quick: AppSettings) -> None:
    with TestClient(create_app(quick), base_url=BASE_URL) as c:
        made = _class(c, 2, guided=True)
        plain = c.post("/api/sessions", json={"config": SMALL}).json()["id"]
        assert c.get(f"/api/sessions/{plain}").json()["guided"] is False  # the default
        c.post("/api/classes/join", json={"code": made["code"]})
        assert c.post(f"/api/sessions/{made['seats'][0]['session']}/capture").status_code == 200
        c.post(f"/api/classes/{made['id']}/pause", json={"paused": True})
    with TestClient(create_app(quick), base_url=BASE_URL) as c:
        board = c.get(f"/api/classes/{made['id']}").json()
        assert (board["code"], board["paused"], board["guided"]) == (made["code"], True, True)
        assert [s["session"] for s in board["seats"]] == [s["session"] for s in made["seats"]]
        assert [s["joined"] for s in board["seats"]] == [True, False]
        assert [s["state"] for s in board["seats"]] == ["asleep", "asleep"]  # not "interrupted": no resume needed
        sid = made["seats"][0]["session"]
        status = c.get(f"/api/sessions/{sid}").json()  # wakes it from its journal
        assert (status["state"], status["iteration"], status["guided"]) == ("ready", 1, True)
        assert c.get(f"/api/sessions/{plain}").json()["guided"] is False
        assert c.post(f"/api/classes/{made['id']}/pause", json={"paused": False}).status_code == 200
        assert c.post("/api/classes/join", json={"code": made["code"]}).json()["seat"] == 2


def test_a_projector_viewer_of_a_seat_only_watches(quick: AppSettings) -> None:
    with TestClient(create_app(quick.replace(scene=True)), base_url=BASE_URL) as c:
        made = _class(c, 1)
        sid = made["seats"][0]["session"]
        assert c.post(f"/api/sessions/{sid}/capture").status_code == 200
        assert c.post(f"/api/sessions/{sid}/plan").status_code == 200
        watch = c.post(f"/api/classes/{made['id']}/seats/1/watch")
        assert watch.status_code == 201 and watch.json()["session"] == sid and "ticket" in watch.json()["url"]
        scene = c.app.state.scene  # type: ignore[attr-defined]
        watcher = scene.viewer(watch.json()["viewer"])
        assert watcher.readonly
        scene._selector(watcher)(2)  # a click on candidate 2 in the projector's view
        assert c.get(f"/api/sessions/{sid}").json()["selected"] != 2
        tab = scene.viewer(c.post("/api/viewer", json={"session": sid}).json()["viewer"])
        scene._selector(tab)(2)  # the same click in the student's own tab selects it
        assert c.get(f"/api/sessions/{sid}").json()["selected"] == 2
