"""The viser scene: one session per viewer (real viser server, raw websocket clients), stable node names,
incremental updates, layers, clicks and the gizmo, the viewer URL."""

from __future__ import annotations

import time
from collections.abc import Iterator
from types import SimpleNamespace
from typing import Any

import numpy as np
import pytest
from fastapi.testclient import TestClient

from app.main import create_app
from app.settings import AppSettings
from tests.viewer_wire import RawViewer, click_message, owner_of, session_labels, session_nodes, wait_for


@pytest.fixture
def scene_client(settings: AppSettings) -> Iterator[TestClient]:
    with TestClient(create_app(settings.replace(scene=True)), base_url="http://127.0.0.1") as c:
        yield c


def open_viewer(client: TestClient, sid: str, origin: str | None = "same") -> tuple[dict[str, Any], RawViewer]:
    """POST /api/viewer for ``sid`` and connect a raw viser client with its ticket; wait until it is drawn."""
    v = client.post("/api/viewer", json={"session": sid})
    assert v.status_code == 201, v.text
    body = v.json()
    port = body["port"]
    ticket = body["url"].split("ticket%3D")[1]
    raw = RawViewer(
        f"ws://127.0.0.1:{port}/?ticket={ticket}", f"http://127.0.0.1:{port}" if origin == "same" else origin
    )
    return body, raw


def drawn(client: TestClient, viewer: str) -> set[str]:
    return set(client.get(f"/api/scene/{viewer}").json()["nodes"])


def test_viewer_url_reports_the_real_port(scene_client: TestClient) -> None:
    server = scene_client.app.state.viser  # type: ignore[attr-defined]
    v = scene_client.get("/api/viewer").json()
    assert v["port"] == server.get_port() > 0
    assert v["url"] == f"http://127.0.0.1:{v['port']}/"


def test_viewer_is_409_without_a_scene(client: TestClient, new_session) -> None:
    sid = new_session(client)
    assert client.get("/api/viewer").status_code == 409
    assert client.post("/api/viewer", json={"session": sid}).status_code == 409
    assert client.get("/api/scene/abc").status_code == 409


def test_a_viewer_draws_its_session_under_stable_names(scene_client: TestClient, planned_session) -> None:
    sid, plan = planned_session(scene_client)
    assert scene_client.post("/api/viewer", json={"session": "nope"}).status_code == 404
    body, raw = open_viewer(scene_client, sid)
    try:
        vid = body["viewer"]
        assert wait_for(lambda: scene_client.get(f"/api/scene/{vid}").json()["connected"])
        nodes = drawn(scene_client, vid)
        for name in ("/map/occupied", "/map/frontier", "/map/unknown", "/candidates", "/nbv", "/cloud/0",
                     "/views/1/frustum", "/views/1/label", "/context/bbox", "/context/turntable", "/context/session",
                     "/ellipsoids/occupied/0", "/ellipsoids/frontier/0", "/context/sectors/lines"):  # fmt: skip
            assert name in nodes, name
        # hidden heavy layers are not sent at all until shown
        assert (
            "/map/empty" not in nodes and "/context/mesh" not in nodes and not any(n.startswith("/gmm/") for n in nodes)
        )
        wb = scene_client.app.state.registry.get(sid)  # type: ignore[attr-defined]
        n_ell = {k: sum(e.kind == k for e in wb.pending.plan.ellipsoids) for k in ("occupied", "frontier")}
        for kind, n in n_ell.items():
            assert sum(x.startswith(f"/ellipsoids/{kind}/") for x in nodes) == n
        # the raw client really received them, with this session's id on its label
        wait_for(lambda: "/candidates" in session_nodes(raw.messages()))
        received = session_nodes(raw.messages())
        assert {"/candidates", "/map/occupied", "/views/1/frustum", "/context/session"} <= received
        assert session_labels(raw.messages()) == {f"session {sid}"}
        # lit by lights only (app/scene/lighting.py): no environment map for a software renderer to prefilter
        by_type = {m.get("type"): m for m in raw.messages()}
        assert by_type["EnvironmentMapMessage"]["hdri_data"] is None
        assert by_type["EnableLightsMessage"] == {"type": "EnableLightsMessage", "enabled": True, "cast_shadow": False}
        assert by_type["HemisphereLightMessage"]["name"] == "/lights/hemisphere"
        # the colour bar: 5th..95th percentile of the eligible scores
        info = scene_client.get(f"/api/scene/{vid}").json()
        eligible = [c["score"] for c in scene_client.get(f"/api/sessions/{sid}/candidates").json() if c["eligible"]]
        assert np.allclose(info["score_range"], np.percentile(eligible, [5, 95]))
        assert "percentile" in info["scale"]

        # approve: the plan's layers are not re-sent, view 2 and new cloud points are appended
        mark = raw.mark()
        r = scene_client.post(
            f"/api/sessions/{sid}/approve", json={"plan_id": plan["plan_id"], "index": plan["best"]["index"]}
        )
        assert r.status_code == 200
        wait_for(lambda: "/views/2/frustum" in session_nodes(raw.messages()[-200:]))
        nodes = drawn(scene_client, vid)
        assert "/views/2/frustum" in nodes and "/nbv" not in nodes and "/cloud/1" in nodes
        after = [m for _, _, ms in raw.frames[mark:] for m in ms]
        resent = session_nodes(after)
        assert not resent & {"/candidates", "/map/occupied", "/views/1/frustum", "/cloud/0", "/context/turntable"}
    finally:
        raw.close()


def test_two_viewers_on_two_sessions_see_only_their_own(scene_client: TestClient, planned_session, new_session) -> None:
    sid_a, _ = planned_session(scene_client)
    sid_b = new_session(scene_client, model="two-boxes")
    body_a, raw_a = open_viewer(scene_client, sid_a)
    body_b, raw_b = open_viewer(scene_client, sid_b)
    try:
        for body in (body_a, body_b):
            assert wait_for(lambda b=body: scene_client.get(f"/api/scene/{b['viewer']}").json()["connected"])
        wait_for(lambda: "/candidates" in session_nodes(raw_a.messages()))
        mark_a = raw_a.mark()
        # everything in B: capture, plan, approve, a click, layers
        assert scene_client.post(f"/api/sessions/{sid_b}/capture").status_code == 200
        plan_b = scene_client.post(f"/api/sessions/{sid_b}/plan").json()
        k = (plan_b["best"]["index"] + 3) % 60
        scene_client.put(f"/api/sessions/{sid_b}/selection", json={"index": k})
        scene_client.put(f"/api/scene/{body_b['viewer']}/layers", json={"empty": True})
        r = scene_client.post(f"/api/sessions/{sid_b}/approve", json={"plan_id": plan_b["plan_id"], "index": k})
        assert r.status_code == 200
        wait_for(lambda: "/views/2/frustum" in session_nodes(raw_b.messages()))
        assert "/views/2/frustum" in session_nodes(raw_b.messages())
        # A received nothing of it; each label names only its own session
        assert session_nodes([m for _, _, ms in raw_a.frames[mark_a:] for m in ms]) == set()
        for raw, sid in ((raw_a, sid_a), (raw_b, sid_b)):
            assert session_labels(raw.messages()) == {f"session {sid}"}
        layers_a = scene_client.get(f"/api/scene/{body_a['viewer']}").json()["layers"]
        assert layers_a["empty"] is False  # B's layer change is B's
    finally:
        raw_a.close()
        raw_b.close()


def test_without_a_ticket_or_from_a_foreign_origin_nothing_is_received_and_clicks_change_nothing(
    scene_client: TestClient, planned_session
) -> None:
    sid, plan = planned_session(scene_client)
    port = scene_client.get("/api/viewer").json()["port"]
    best = plan["best"]["index"]
    k = (best + 7) % 60
    bare = RawViewer(f"ws://127.0.0.1:{port}/", f"http://127.0.0.1:{port}")
    _, foreign = open_viewer(scene_client, sid, origin="http://evil.example")
    noorigin = RawViewer(f"ws://127.0.0.1:{port}/?ticket=made-up", None)
    try:
        wait_for(lambda: foreign.closed is not None and noorigin.closed is not None, timeout=5)
        assert foreign.closed is not None and foreign.closed[0] == 4003 and "evil.example" in foreign.closed[1]
        assert noorigin.closed is not None and noorigin.closed[0] == 4003
        for raw in (bare, foreign, noorigin):
            for owner in ("", "0", "1", "2", "3", "4"):  # whatever scope it pretends to click in
                raw.send(click_message("/candidates", k, owner))
        # a real, bound viewer proves clicks do arrive when they may
        good_body, good = open_viewer(scene_client, sid)
        try:
            wait_for(lambda: "/candidates" in session_nodes(good.messages()))
            owner = owner_of(good.messages(), "/candidates")
            bare.send(click_message("/candidates", k, owner))  # even with the bound viewer's owner stamp
            good.send(click_message("/nonexistent", 0, owner))  # a round trip on the good socket after it
            wait_for(lambda: False, timeout=0.5)
            assert scene_client.get(f"/api/sessions/{sid}").json()["selected"] == best
            for name, raw in (("bare", bare), ("foreign", foreign), ("noorigin", noorigin)):
                assert session_nodes(raw.messages()) == set(), name
            good.send(click_message("/candidates", k, owner_of(good.messages(), "/candidates")))
            assert wait_for(lambda: scene_client.get(f"/api/sessions/{sid}").json()["selected"] == k)
        finally:
            good.close()
        # a used ticket (the good viewer's) binds nothing a second time; the foreign viewer's ticket was never
        # redeemed (its Origin was refused first), so it is not the one to try
        again = RawViewer(
            f"ws://127.0.0.1:{port}/?ticket={good_body['url'].split('ticket%3D')[1]}", f"http://127.0.0.1:{port}"
        )
        try:
            for owner in ("", "0", "1", "2", "3", "4", "5"):
                again.send(click_message("/candidates", best, owner))
            wait_for(lambda: len(again.frames) > 0, timeout=3)
            assert session_nodes(again.messages()) == set()
            assert scene_client.get(f"/api/sessions/{sid}").json()["selected"] == k
        finally:
            again.close()
    finally:
        for raw in (bare, foreign, noorigin):
            raw.close()


def test_layers_toggle_visibility_per_viewer(scene_client: TestClient, planned_session) -> None:
    sid, _ = planned_session(scene_client)
    body, raw = open_viewer(scene_client, sid)
    try:
        vid = body["viewer"]
        assert wait_for(lambda: scene_client.get(f"/api/scene/{vid}").json()["connected"])
        r = scene_client.put(f"/api/scene/{vid}/layers", json={"empty": True, "ellipsoids": False, "gmm": True})
        assert r.json()["empty"] is True and r.json()["ellipsoids"] is False
        nodes = drawn(scene_client, vid)
        assert "/map/empty" in nodes and any(n.startswith("/gmm/") for n in nodes)
        r = scene_client.put(f"/api/scene/{vid}/layers", json={"nonsense": True})
        assert r.status_code == 422 and "nonsense" in r.json()["detail"]
        assert scene_client.get("/api/scene/unknown-viewer").status_code == 404
    finally:
        raw.close()


def test_the_gizmo_and_the_camera_act_on_the_viewers_session(scene_client: TestClient, planned_session) -> None:
    sid, _ = planned_session(scene_client)
    body, raw = open_viewer(scene_client, sid)
    try:
        vid = body["viewer"]
        assert wait_for(lambda: scene_client.get(f"/api/scene/{vid}").json()["connected"])
        scene_client.put(f"/api/scene/{vid}/layers", json={"gizmo": True})
        assert "/override/gizmo" in drawn(scene_client, vid)
        drawing = scene_client.app.state.scene.viewer(vid).drawing  # type: ignore[attr-defined]
        target = SimpleNamespace(wxyz=np.array([1.0, 0.0, 0.0, 0.0]), position=np.array([0.0, 0.0, -0.3]))
        drawing._on_gizmo(SimpleNamespace(phase="end", target=target))
        custom = scene_client.get(f"/api/sessions/{sid}").json()["custom_pose"]
        assert custom["reachable"] is False and custom["pose"]["position"] == [0.0, 0.0, -0.3]
        assert scene_client.post(f"/api/scene/{vid}/camera", json={"candidate": 5}).json() == {"clients": 1}
        assert scene_client.post(f"/api/scene/{vid}/camera", json={"candidate": 500}).status_code == 404
        assert scene_client.post(f"/api/scene/{vid}/camera", json={}).status_code == 422
    finally:
        raw.close()


def test_a_deleted_session_empties_its_viewers(scene_client: TestClient, planned_session) -> None:
    sid, _ = planned_session(scene_client)
    body, raw = open_viewer(scene_client, sid)
    try:
        vid = body["viewer"]
        assert wait_for(lambda: "/candidates" in drawn(scene_client, vid))
        assert scene_client.delete(f"/api/sessions/{sid}").status_code == 204
        assert drawn(scene_client, vid) == set()
    finally:
        raw.close()


def test_a_busy_viser_port_moves_the_viewer(settings: AppSettings) -> None:
    import socket

    with socket.socket() as busy:
        busy.bind(("127.0.0.1", 0))
        busy.listen()
        port = busy.getsockname()[1]
        with TestClient(create_app(settings.replace(scene=True, viser_port=port)), base_url="http://127.0.0.1") as c:
            v = c.get("/api/viewer").json()
            assert v["port"] != port and v["url"].endswith(f":{v['port']}/")


def test_viser_off_loopback_needs_a_token(settings: AppSettings) -> None:
    with pytest.raises(ValueError, match="3D viewer"):
        create_app(settings.replace(scene=True, viser_host="0.0.0.0"))
    create_app(settings.replace(scene=True, viser_host="0.0.0.0", token="t" * 32))


def test_default_model_may_be_a_file_path(settings: AppSettings, models_dir) -> None:
    import dataclasses

    path = str(models_dir / "cube.obj")
    devices = dataclasses.replace(settings.devices, model=path)
    with TestClient(create_app(settings.replace(devices=devices)), base_url="http://127.0.0.1") as c:
        assert path in [m["name"] for m in c.get("/api/models").json()]
        sid = c.post("/api/sessions", json={}).json()["id"]
        assert c.get(f"/api/sessions/{sid}").json()["model"] == path


def test_tickets_are_single_use_and_expire() -> None:
    import time

    from app.scene.tickets import TicketBook

    book = TicketBook(ttl=0.2)
    t = book.issue("abcd1234")
    assert book.redeem(t.secret) == t and book.redeem(t.secret) is None
    late = book.issue("abcd1234")
    time.sleep(0.3)
    assert book.redeem(late.secret) is None
    with pytest.raises(ValueError, match="ttl"):
        TicketBook(ttl=0)


def test_two_viewers_of_one_session_stay_in_step(scene_client: TestClient, planned_session) -> None:
    sid, plan = planned_session(scene_client)
    (b1, r1), (b2, r2) = open_viewer(scene_client, sid), open_viewer(scene_client, sid)
    try:
        for b in (b1, b2):
            assert wait_for(lambda b=b: "/candidates" in drawn(scene_client, b["viewer"]))
        body = {"plan_id": plan["plan_id"], "index": plan["best"]["index"]}
        assert scene_client.post(f"/api/sessions/{sid}/approve", json=body).status_code == 200
        for raw in (r1, r2):
            assert wait_for(lambda raw=raw: "/views/2/frustum" in session_nodes(raw.messages()))
        assert drawn(scene_client, b1["viewer"]) == drawn(scene_client, b2["viewer"])
        # the other tab's approve of the same plan is refused as used
        r = scene_client.post(f"/api/sessions/{sid}/approve", json=body)
        assert r.status_code == 409 and "already used" in r.json()["detail"]
    finally:
        r1.close()
        r2.close()


def test_the_surface_layer_is_sent_when_shown_and_again_only_when_it_changed(
    scene_client: TestClient, planned_session
) -> None:
    sid, plan = planned_session(scene_client)
    body, raw = open_viewer(scene_client, sid)

    def surface_meshes() -> list[dict[str, Any]]:
        return [m for m in raw.messages() if m.get("name") == "/surface" and "Mesh" in m.get("type", "")]

    try:
        vid = body["viewer"]
        assert wait_for(lambda: scene_client.get(f"/api/scene/{vid}").json()["connected"])
        layers = scene_client.get(f"/api/scene/{vid}").json()["layers"]
        assert layers["surface"] is False and "/surface" not in drawn(scene_client, vid)  # hidden: not sent
        assert scene_client.put(f"/api/scene/{vid}/layers", json={"surface": True}).json()["surface"] is True
        assert "/surface" in drawn(scene_client, vid)
        assert wait_for(lambda: len(surface_meshes()) == 1)
        first = surface_meshes()[0]
        layer = scene_client.app.state.registry.get(sid).surface.layer  # type: ignore[attr-defined]
        assert 0 < layer.triangles <= 15_000
        props = first["props"]
        assert props["vertices"]["nbytes"] == 12 * len(layer.vertices)  # float32, as the layer's budget counts
        assert props["faces"]["nbytes"] == 12 * layer.triangles
        # off and on again, a new plan: the same surface, not sent again
        scene_client.put(f"/api/scene/{vid}/layers", json={"surface": False})
        scene_client.put(f"/api/scene/{vid}/layers", json={"surface": True})
        plan = scene_client.post(f"/api/sessions/{sid}/plan").json()
        time.sleep(0.3)
        assert len(surface_meshes()) == 1
        # a new view changes the surface: sent once more
        body2 = {"plan_id": plan["plan_id"], "index": plan["best"]["index"]}
        assert scene_client.post(f"/api/sessions/{sid}/approve", json=body2).status_code == 200
        assert wait_for(lambda: len(surface_meshes()) == 2)
    finally:
        raw.close()
