"""The viser scene: node names drawn from the PlanResult, layers, focus, the viewer URL, clicks and the gizmo."""

from __future__ import annotations

from collections.abc import Iterator
from types import SimpleNamespace

import numpy as np
import pytest
from fastapi.testclient import TestClient

from app.main import create_app
from app.settings import AppSettings


@pytest.fixture
def scene_client(settings: AppSettings) -> Iterator[TestClient]:
    with TestClient(create_app(settings.replace(scene=True)), base_url="http://127.0.0.1") as c:
        yield c


def test_viewer_url_reports_the_real_port(scene_client: TestClient) -> None:
    server = scene_client.app.state.viser  # type: ignore[attr-defined]
    v = scene_client.get("/api/viewer").json()
    assert v["port"] == server.get_port() > 0
    assert v["url"] == f"http://127.0.0.1:{v['port']}/"


def test_viewer_is_409_without_a_scene(client: TestClient) -> None:
    assert client.get("/api/viewer").status_code == 409
    assert client.get("/api/scene").status_code == 409


def test_scene_draws_the_plan_under_stable_names(scene_client: TestClient, planned_session) -> None:
    sid, plan = planned_session(scene_client)
    info = scene_client.get("/api/scene").json()
    assert info["session"] == sid  # the first session is focused
    nodes = set(info["nodes"])
    for name in ("/map/occupied", "/map/frontier", "/map/unknown", "/map/empty", "/candidates", "/nbv", "/cloud",
                 "/views/1/frustum", "/views/1/label", "/context/bbox", "/context/turntable", "/context/mesh",
                 "/ellipsoids/occupied/0", "/ellipsoids/frontier/0", "/context/sectors/lines"):  # fmt: skip
        assert name in nodes, name
    server = scene_client.app.state.viser  # type: ignore[attr-defined]
    for name in nodes:
        assert server.scene.get_handle_by_name(name) is not None, name
    wb = scene_client.app.state.registry.get(sid)  # type: ignore[attr-defined]
    n_ell = {k: sum(e.kind == k for e in wb.pending.plan.ellipsoids) for k in ("occupied", "frontier")}
    for kind, n in n_ell.items():
        assert sum(x.startswith(f"/ellipsoids/{kind}/") for x in nodes) == n
    lo, hi = info["score_range"]
    eligible = [c["score"] for c in scene_client.get(f"/api/sessions/{sid}/candidates").json() if c["eligible"]]
    assert np.isclose(lo, min(eligible)) and np.isclose(hi, max(eligible))
    # defaults: empty voxels, GMM debug ellipsoids and the ground-truth mesh are hidden
    for name, visible in (("/map/empty", False), ("/gmm", False), ("/context/mesh", False), ("/map/occupied", True)):
        assert server.scene.get_handle_by_name(name).visible is visible

    # after approval the chosen view is gone and view 2 appears
    body = {"plan_id": plan["plan_id"], "index": plan["best"]["index"]}
    assert scene_client.post(f"/api/sessions/{sid}/approve", json=body).status_code == 200
    nodes = set(scene_client.get("/api/scene").json()["nodes"])
    assert "/views/2/frustum" in nodes and "/nbv" not in nodes


def test_layers_toggle_visibility(scene_client: TestClient, planned_session) -> None:
    planned_session(scene_client)
    server = scene_client.app.state.viser  # type: ignore[attr-defined]
    r = scene_client.put("/api/scene/layers", json={"empty": True, "ellipsoids": False})
    assert r.json()["empty"] is True and r.json()["ellipsoids"] is False
    assert server.scene.get_handle_by_name("/map/empty").visible is True
    assert server.scene.get_handle_by_name("/ellipsoids").visible is False
    r = scene_client.put("/api/scene/layers", json={"nonsense": True})
    assert r.status_code == 422 and "nonsense" in r.json()["detail"]


def test_focus_switches_sessions(scene_client: TestClient, new_session, planned_session) -> None:
    sid_a, _ = planned_session(scene_client)
    sid_b = new_session(scene_client)
    assert scene_client.get("/api/scene").json()["session"] == sid_a
    info = scene_client.put("/api/scene", json={"session": sid_b}).json()
    assert info["session"] == sid_b and "/candidates" not in info["nodes"]
    assert scene_client.put("/api/scene", json={"session": "nope"}).status_code == 404
    scene_client.delete(f"/api/sessions/{sid_b}")
    assert scene_client.get("/api/scene").json()["session"] is None


def test_a_click_on_a_candidate_selects_it(scene_client: TestClient, planned_session) -> None:
    sid, plan = planned_session(scene_client)
    scene = scene_client.app.state.scene  # type: ignore[attr-defined]
    k = (plan["best"]["index"] + 7) % 60
    scene._on_candidate_click(SimpleNamespace(instance_index=k))
    assert scene_client.get(f"/api/sessions/{sid}").json()["selected"] == k
    assert "/selected" in scene_client.get("/api/scene").json()["nodes"]
    # without an instance index the marker nearest the click ray wins
    wb = scene_client.app.state.registry.get(sid)  # type: ignore[attr-defined]
    target = wb.pending.plan.candidates[3].position
    origin = target + np.array([0.0, 0.0, 1.0])
    scene._on_candidate_click(SimpleNamespace(instance_index=None, ray_origin=origin, ray_direction=(0.0, 0.0, -1.0)))
    assert scene_client.get(f"/api/sessions/{sid}").json()["selected"] == 3


def test_the_gizmo_proposes_a_custom_pose(scene_client: TestClient, planned_session) -> None:
    sid, _ = planned_session(scene_client)
    scene_client.put("/api/scene/layers", json={"gizmo": True})
    assert "/override/gizmo" in scene_client.get("/api/scene").json()["nodes"]
    scene = scene_client.app.state.scene  # type: ignore[attr-defined]
    target = SimpleNamespace(wxyz=np.array([1.0, 0.0, 0.0, 0.0]), position=np.array([0.0, 0.0, -0.3]))
    scene._on_gizmo(SimpleNamespace(phase="end", target=target))
    custom = scene_client.get(f"/api/sessions/{sid}").json()["custom_pose"]
    assert custom["reachable"] is False and custom["pose"]["position"] == [0.0, 0.0, -0.3]


def test_camera_points_at_a_candidate(scene_client: TestClient, planned_session) -> None:
    planned_session(scene_client)
    assert scene_client.post("/api/scene/camera", json={"candidate": 5}).json() == {"clients": 0}
    assert scene_client.post("/api/scene/camera", json={"candidate": 500}).status_code == 404
    assert scene_client.post("/api/scene/camera", json={}).status_code == 422
    server = scene_client.app.state.viser  # type: ignore[attr-defined]
    assert np.linalg.norm(server.initial_camera.position - server.initial_camera.look_at) == pytest.approx(0.3)


def test_a_busy_viser_port_moves_the_viewer(settings: AppSettings) -> None:
    import socket

    with socket.socket() as busy:
        busy.bind(("127.0.0.1", 0))
        busy.listen()
        port = busy.getsockname()[1]
        with TestClient(create_app(settings.replace(scene=True, viser_port=port)), base_url="http://127.0.0.1") as c:
            v = c.get("/api/viewer").json()
            assert v["port"] != port and v["url"].endswith(f":{v['port']}/")


def test_default_model_may_be_a_file_path(settings: AppSettings, models_dir) -> None:
    import dataclasses

    path = str(models_dir / "cube.obj")
    devices = dataclasses.replace(settings.devices, model=path)
    with TestClient(create_app(settings.replace(devices=devices)), base_url="http://127.0.0.1") as c:
        assert path in [m["name"] for m in c.get("/api/models").json()]
        sid = c.post("/api/sessions", json={}).json()["id"]
        assert c.get(f"/api/sessions/{sid}").json()["model"] == path
