"""Every error status of the API: 404, 409, 413, 422, 503 -- and nothing moves when a request is refused."""

from __future__ import annotations

import json
from collections.abc import Iterator

import pytest
from apphelpers import BASE_URL, SMALL
from fastapi.testclient import TestClient

from app.main import create_app
from app.settings import AppSettings
from devices.protocols import DeviceError
from tests.helpers import with_small_costs


def detail(r) -> str:
    body = r.json()
    assert set(body) == {"detail"}, body
    return str(body["detail"])


@pytest.mark.parametrize(
    ("method", "path"),
    [
        ("get", ""),
        ("delete", ""),
        ("post", "/capture"),
        ("post", "/plan"),
        ("get", "/candidates"),
        ("get", "/candidates/0"),
        ("get", "/candidates/0/projection.png"),
        ("post", "/step"),
        ("post", "/auto"),
        ("post", "/stop"),
        ("get", "/metrics"),
        ("get", "/cloud.ply"),
        ("get", "/export"),
    ],
)
def test_unknown_session_is_404(client: TestClient, method: str, path: str) -> None:
    r = getattr(client, method)(f"/api/sessions/nope{path}")
    assert r.status_code == 404
    assert "nope" in detail(r)


def test_unknown_candidate_is_404(client: TestClient, planned_session) -> None:
    sid, plan = planned_session(client)
    for path in ("/candidates/60", "/candidates/999/projection.png"):
        r = client.get(f"/api/sessions/{sid}{path}")
        assert r.status_code == 404 and "candidate" in detail(r)
    r = client.put(f"/api/sessions/{sid}/selection", json={"index": 60})
    assert r.status_code == 404
    r = client.post(f"/api/sessions/{sid}/approve", json={"plan_id": plan["plan_id"], "index": 60})
    assert r.status_code == 404
    st = client.get(f"/api/sessions/{sid}").json()
    assert (st["moves"], st["iteration"], st["state"]) == (1, 1, "planned")


def test_wrong_state_is_409(client: TestClient, new_session) -> None:
    sid = new_session(client)
    for path in ("/plan", "/step", "/auto"):
        r = client.post(f"/api/sessions/{sid}{path}")
        assert r.status_code == 409 and "capture first" in detail(r)
    assert client.get(f"/api/sessions/{sid}/candidates").status_code == 409
    r = client.post(f"/api/sessions/{sid}/approve", json={"plan_id": "abc", "index": 0})
    assert r.status_code == 409
    assert client.post(f"/api/sessions/{sid}/capture").status_code == 200
    r = client.post(f"/api/sessions/{sid}/capture")
    assert r.status_code == 409 and "already captured" in detail(r)
    r = client.put(f"/api/sessions/{sid}/selection", json={"index": 0})
    assert r.status_code == 409
    assert client.get(f"/api/sessions/{sid}").json()["moves"] == 1


def test_stale_and_reused_plan_ids_are_409_and_move_nothing(client: TestClient, planned_session) -> None:
    sid, first = planned_session(client)
    second = client.post(f"/api/sessions/{sid}/plan").json()
    assert second["plan_id"] != first["plan_id"]
    r = client.post(f"/api/sessions/{sid}/approve", json={"plan_id": first["plan_id"], "index": first["best"]["index"]})
    assert r.status_code == 409 and "stale" in detail(r)
    assert client.get(f"/api/sessions/{sid}").json()["moves"] == 1

    body = {"plan_id": second["plan_id"], "index": second["best"]["index"]}
    assert client.post(f"/api/sessions/{sid}/approve", json=body).status_code == 200
    r = client.post(f"/api/sessions/{sid}/approve", json=body)
    assert r.status_code == 409 and "already used" in detail(r)
    st = client.get(f"/api/sessions/{sid}").json()
    assert (st["moves"], st["iteration"]) == (2, 2)


def test_unreachable_override_is_422_and_moves_nothing(client: TestClient, planned_session) -> None:
    sid, plan = planned_session(client)
    below = {"position": [0.1, 0.0, -0.2], "wxyz": [1.0, 0.0, 0.0, 0.0]}
    far = {"position": [3.0, 0.0, 0.5], "wxyz": [1.0, 0.0, 0.0, 0.0]}
    for pose in (below, far):
        custom = client.put(f"/api/sessions/{sid}/custom_pose", json={"pose": pose}).json()
        assert custom["reachable"] is False and "unreachable" in custom["reason"]
        r = client.post(f"/api/sessions/{sid}/approve", json={"plan_id": plan["plan_id"], "pose": pose})
        assert r.status_code == 422 and "unreachable" in detail(r)
    st = client.get(f"/api/sessions/{sid}").json()
    assert (st["moves"], st["iteration"], st["state"]) == (1, 1, "planned")
    # the plan is still pending and can be approved
    body = {"plan_id": plan["plan_id"], "index": plan["best"]["index"]}
    assert client.post(f"/api/sessions/{sid}/approve", json=body).status_code == 200


@pytest.mark.parametrize(
    "body",
    [
        {"config": {"voxel": {"resolution": -1}}},
        {"config": {"voxel": {"bogus": 1}}},
        {"config": {"nonsense": {}}},
        {"config": {"cluster": {"t_min": 9, "t_max": 3}}},
        {"config": {"candidates": {"count": "many"}}},
        {"config": {"partitions": {"revisit_deg": 180}}},
        {"seed": -1},
        {"model": "no-such-object"},
        {"model": "../../etc/passwd"},
        {"unexpected": 1},
    ],
)
def test_bad_session_parameters_are_422(client: TestClient, body: dict) -> None:
    r = client.post("/api/sessions", json=body)
    assert r.status_code == 422, r.text
    assert "detail" in r.json()
    assert client.get("/api/sessions").json() == []


@pytest.fixture(scope="module")
def bad_approve_target(tmp_path_factory: pytest.TempPathFactory) -> Iterator[tuple[TestClient, str, dict]]:
    """One planned session for every bad approve body (client, id, plan): a refused body moves nothing, so each
    case also finds the session as the cases before it left it (a capture and a plan a case cost 1-2 s)."""
    tmp = tmp_path_factory.mktemp("bad-approve")
    settings = with_small_costs(AppSettings(viser_port=0, scene=False, models_dir=tmp, data_dir=tmp / "data"))
    with TestClient(create_app(settings), base_url=BASE_URL) as client:
        r = client.post("/api/sessions", json={"model": "l-block", "config": SMALL, "seed": 0})
        assert r.status_code == 201, r.text
        sid = r.json()["id"]
        assert client.post(f"/api/sessions/{sid}/capture").status_code == 200
        r = client.post(f"/api/sessions/{sid}/plan")
        assert r.status_code == 200, r.text
        yield client, sid, r.json()


@pytest.mark.parametrize(
    "body",
    [
        {"plan_id": "PLAN", "index": 0, "pose": {"position": [0, 0, 0.3], "wxyz": [1, 0, 0, 0]}},
        {"plan_id": "PLAN"},
        {"plan_id": "PLAN", "index": -1},
        {"plan_id": "PLAN", "pose": {"position": [0, 0], "wxyz": [1, 0, 0, 0]}},
        {"plan_id": "PLAN", "pose": {"position": [0, 0, 0.3], "wxyz": [0, 0, 0, 0]}},
        {"plan_id": "PLAN", "pose": {"position": [float("nan"), 0, 0.3], "wxyz": [1, 0, 0, 0]}},
    ],
)
def test_bad_approve_bodies_are_422(bad_approve_target: tuple[TestClient, str, dict], body: dict) -> None:
    client, sid, plan = bad_approve_target
    body = {**body, "plan_id": plan["plan_id"]}
    raw = json.dumps(body)  # allows NaN, which a strict JSON encoder would refuse to send
    r = client.post(f"/api/sessions/{sid}/approve", content=raw, headers={"content-type": "application/json"})
    assert r.status_code == 422, r.text
    st = client.get(f"/api/sessions/{sid}").json()
    assert (st["moves"], st["state"]) == (1, "planned")


def test_bad_counts_are_422(client: TestClient, new_session) -> None:
    sid = new_session(client)
    for path, body in (("/step", {"count": 0}), ("/auto", {"count": 1000}), ("/step", {"count": "x"})):
        assert client.post(f"/api/sessions/{sid}{path}", json=body).status_code == 422


def test_uploads(tmp_path, models_dir, cube_obj) -> None:
    settings = AppSettings(
        viser_port=0, scene=False, models_dir=models_dir, data_dir=tmp_path / "d", max_upload_bytes=2000
    )
    with TestClient(create_app(settings), base_url="http://127.0.0.1") as client:
        r = client.post("/api/models", files={"file": ("my cube!.obj", cube_obj.encode(), "text/plain")})
        assert r.status_code == 201, r.text
        name = r.json()["name"]
        assert name.startswith("uploads/my_cube-") and name.endswith(".obj")
        assert name in [m["name"] for m in client.get("/api/models").json()]
        assert client.post("/api/sessions", json={"model": name}).status_code == 201

        r = client.post("/api/models", files={"file": ("big.obj", b"v 0 0 0\n" * 500, "text/plain")})
        assert r.status_code == 413
        r = client.post("/api/models", files={"file": ("junk.obj", b"this is not a mesh", "text/plain")})
        assert r.status_code == 422
        r = client.post("/api/models", files={"file": ("x.exe", b"MZ", "application/octet-stream")})
        assert r.status_code == 422 and "unsupported" in detail(r)
        stored = sorted(p.name for p in (tmp_path / "d" / "uploads").iterdir())
        assert stored == [name.removeprefix("uploads/")]


def test_device_fault_gives_error_state_and_replanning_recovers(client: TestClient, planned_session) -> None:
    sid, plan = planned_session(client)
    wb = client.app.state.registry.get(sid)  # type: ignore[attr-defined]
    wb.cell.arm.fail_next = DeviceError("arm stalled")
    before = wb.planner.voxel_map.classes.copy()
    r = client.post(f"/api/sessions/{sid}/approve", json={"plan_id": plan["plan_id"], "index": plan["best"]["index"]})
    assert r.status_code == 503 and "arm stalled" in detail(r)
    st = client.get(f"/api/sessions/{sid}").json()
    assert st["state"] == "error" and "arm stalled" in st["error"] and st["iteration"] == 1
    assert (wb.planner.voxel_map.classes == before).all()
    plan = client.post(f"/api/sessions/{sid}/plan").json()
    st = client.post(f"/api/sessions/{sid}/approve", json={"plan_id": plan["plan_id"], "index": plan["best"]["index"]})
    assert st.json()["iteration"] == 2 and st.json()["error"] is None
