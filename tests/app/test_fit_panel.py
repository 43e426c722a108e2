"""Debugging a fit through the API and a raw viser client (real server, real planner, the session's worker): the
Fit panel's rows against the plan and the candidate breakdown, the clusters layer's per-voxel colours against
the fit's labels and the ellipsoids' containment, a fit at another T that leaves the plan alone, the focus
(by REST and by a click in the scene), bad input, and the viewer's state pushed to the page's event socket."""

from __future__ import annotations

import threading
import time
from collections.abc import Iterator
from typing import Any

import numpy as np
import pytest
import websockets
from apphelpers import BASE_URL, CUBE_OBJ, SMALL
from fastapi.testclient import TestClient

from app.main import create_app
from app.settings import AppSettings
from tests.viewer_buffers import decode_frame_arrays
from tests.viewer_wire import RawViewer, click_message, decode_frame, owner_of, wait_for


class BufferedViewer(RawViewer):
    """A RawViewer that keeps every frame's bytes too (to decode the binary buffers)."""

    def __init__(self, url: str, origin: str | None) -> None:
        self.raw: list[bytes] = []
        super().__init__(url, origin)

    def _read(self) -> None:
        try:
            for data in self.ws:
                assert isinstance(data, bytes)
                with self._lock:
                    self.raw.append(data)
                    self.frames.append((time.perf_counter(), len(data), decode_frame(data)))
        except websockets.exceptions.ConnectionClosed:
            pass

    def arrays_since(self, mark: int) -> list[dict[str, Any]]:
        with self._lock:
            raw = self.raw[mark:]
        return [m for data in raw for m in decode_frame_arrays(data)]


@pytest.fixture(scope="module")
def env(tmp_path_factory: pytest.TempPathFactory) -> Iterator[dict[str, Any]]:
    tmp = tmp_path_factory.mktemp("fit")
    (tmp / "models").mkdir()
    (tmp / "models" / "cube.obj").write_text(CUBE_OBJ)
    settings = AppSettings(viser_port=0, scene=True, models_dir=tmp / "models", data_dir=tmp / "data")
    with TestClient(create_app(settings), base_url=BASE_URL) as client:
        sid = client.post("/api/sessions", json={"model": "l-block", "config": SMALL}).json()["id"]
        assert client.post(f"/api/sessions/{sid}/capture").status_code == 200
        plan = client.post(f"/api/sessions/{sid}/plan").json()
        body = client.post("/api/viewer", json={"session": sid}).json()
        ticket = body["url"].split("ticket%3D")[1]
        port = body["port"]
        raw = BufferedViewer(f"ws://127.0.0.1:{port}/?ticket={ticket}", f"http://127.0.0.1:{port}")
        vid = body["viewer"]
        assert wait_for(lambda: client.get(f"/api/scene/{vid}").json()["connected"])
        try:
            yield {"client": client, "sid": sid, "plan": plan, "vid": vid, "raw": raw}
        finally:
            raw.close()


def _plan_of(env: dict[str, Any]) -> Any:
    return env["client"].app.state.registry.get(env["sid"]).plan_for().plan


def test_the_fit_rows_are_the_plan_s_ellipsoids_worst_filled_first(env: dict[str, Any]) -> None:
    client, sid, vid = env["client"], env["sid"], env["vid"]
    plan = _plan_of(env)
    info = client.get(f"/api/scene/{vid}/fit").json()
    assert info["plan_id"] == env["plan"]["plan_id"] and info["focus"] is None
    res = plan.voxels.resolution
    by_label = {r["label"]: r for r in info["rows"]}
    counts = {"occupied": 0, "frontier": 0}
    for e in plan.ellipsoids:
        label = f"{e.kind[0].upper()}{counts[e.kind]}"
        counts[e.kind] += 1
        row = by_label[label]
        volume = 4 / 3 * np.pi * np.prod(e.axes)
        assert row["voxels"] == e.n_points and row["volume"] == pytest.approx(volume)
        assert row["fill"] == pytest.approx(e.n_points * res**3 / volume)
        assert 0 < row["weight"] <= 1
    assert len(by_label) == len(plan.ellipsoids)
    for kind in ("occupied", "frontier"):
        rows = [r for r in info["rows"] if r["kind"] == kind]
        assert [r["fill"] for r in rows] == sorted(r["fill"] for r in rows)  # worst-filled first
        fit = next(f for f in plan.fits if f.kind == kind)
        # the weights of the clusters that took voxels: at most 1 (an empty component's weight is left out)
        assert 0 < sum(r["weight"] for r in rows) <= 1 + 1e-9
        assert sum(r["voxels"] for r in rows) == fit.n_points == len(fit.labels)
        k = next(x for x in info["kinds"] if x["kind"] == kind)
        assert k["t_plan"] == fit.t_chosen and k["t_shown"] == len(rows) and not k["refit"]
    # w·L of the selected candidate: the inspector's breakdown of that candidate
    selected = info["selected"]
    assert selected is not None
    detail = client.get(f"/api/sessions/{sid}/candidates/{selected}").json()
    for term in detail["ellipsoids"]:
        assert by_label[term["label"]]["weighted"] == pytest.approx(term["weighted"])


def _cluster_clouds(env: dict[str, Any], mark: int) -> dict[str, tuple[np.ndarray, np.ndarray]]:
    out = {}
    for m in env["raw"].arrays_since(mark):
        name = m.get("name", "")
        if name.startswith("/clusters/") and name.endswith("/voxels") and "PointCloud" in m["type"]:
            props = m["props"]
            out[name.split("/")[2]] = (
                np.asarray(props["points"], dtype=np.float64).reshape(-1, 3),
                np.asarray(props["colors"]).reshape(-1, 3),
            )
    return out


def test_the_clusters_layer_colours_each_voxel_by_its_cluster(env: dict[str, Any]) -> None:
    client, vid, raw = env["client"], env["vid"], env["raw"]
    plan = _plan_of(env)
    mark = raw.mark()
    layers = client.put(f"/api/scene/{vid}/layers", json={"clusters": True}).json()
    assert layers["clusters"] is True
    assert wait_for(lambda: len(_cluster_clouds(env, mark)) == 2)
    clouds = _cluster_clouds(env, mark)
    rows = client.get(f"/api/scene/{vid}/fit").json()["rows"]
    for kind in ("occupied", "frontier"):
        points, colors = clouds[kind]
        voxels = plan.voxels.occupied if kind == "occupied" else plan.voxels.frontier
        assert len(points) == len(voxels)
        assert np.allclose(points, voxels, atol=2e-3)  # float16 on the wire
        labels = next(f for f in plan.fits if f.kind == kind).labels
        color_of = {r["index"]: tuple(r["color"]) for r in rows if r["kind"] == kind}
        assert len(set(color_of.values())) == len(color_of)  # one colour per cluster
        assert [tuple(c) for c in colors] == [color_of[int(k)] for k in labels]
        # each voxel is inside the ellipsoid of the cluster its colour names
        mine = [e for e in plan.ellipsoids if e.kind == kind]
        index_of = {c: i for i, c in color_of.items()}
        for p, c in zip(voxels, colors, strict=True):
            e = mine[index_of[tuple(c)]]
            y = p - e.center
            assert y @ e.shape_matrix @ y <= 1 + 1e-9
    nodes = set(client.get(f"/api/scene/{vid}").json()["nodes"])
    n_occ = sum(e.kind == "occupied" for e in plan.ellipsoids)
    assert {f"/clusters/occupied/{i}" for i in range(n_occ)} <= nodes and "/clusters/labels/O0" in nodes


def test_a_fit_at_another_t_leaves_the_plan_alone(env: dict[str, Any]) -> None:
    client, sid, vid, raw = env["client"], env["sid"], env["vid"], env["raw"]
    plan = _plan_of(env)
    before = client.get(f"/api/sessions/{sid}").json()
    t_plan = next(f for f in plan.fits if f.kind == "frontier").t_chosen
    t = 3 if t_plan != 3 else 4
    worker = client.app.state.registry.get(sid).worker  # type: ignore[attr-defined]
    jobs = worker.jobs
    mark = raw.mark()
    info = client.put(f"/api/scene/{vid}/fit", json={"kind": "frontier", "t": t}).json()
    assert worker.jobs == jobs + 1  # fitted in the session's worker process
    k = next(x for x in info["kinds"] if x["kind"] == "frontier")
    assert k["refit"] and k["t_shown"] == t and k["ellipsoids"] == t and k["t_plan"] == t_plan
    assert isinstance(k["bic"], float)
    rows = [r for r in info["rows"] if r["kind"] == "frontier"]
    assert len(rows) == t and all(r["weighted"] is None for r in rows)
    assert sum(r["voxels"] for r in rows) == len(plan.voxels.frontier)
    after = client.get(f"/api/sessions/{sid}").json()
    assert after["pending_plan"]["plan_id"] == before["pending_plan"]["plan_id"] == info["plan_id"]
    assert after["state"] == before["state"] == "planned" and _plan_of(env) is plan

    def sent() -> set[str]:
        return {
            m["name"] for _, _, ms in raw.frames[mark:] for m in ms
            if m.get("name", "").startswith("/clusters/frontier/") and "Icosphere" in m.get("type", "")
        }  # fmt: skip

    assert wait_for(lambda: len(sent()) >= t)
    assert sent() == {f"/clusters/frontier/{i}" for i in range(t)}
    clouds = _cluster_clouds(env, mark)
    assert len({tuple(c) for c in clouds["frontier"][1]}) == t  # the refit's clusters coloured
    back = client.put(f"/api/scene/{vid}/fit", json={"kind": "frontier", "t": None}).json()
    k = next(x for x in back["kinds"] if x["kind"] == "frontier")
    assert not k["refit"] and k["t_shown"] == sum(e.kind == "frontier" for e in plan.ellipsoids)


def test_focus_by_rest_and_by_a_click_and_bad_input_changes_nothing(env: dict[str, Any]) -> None:
    client, vid, raw = env["client"], env["vid"], env["raw"]
    client.put(f"/api/scene/{vid}/layers", json={"clusters": True})
    assert client.put(f"/api/scene/{vid}/fit/focus", json={"label": "O0"}).json()["focus"] == "O0"
    for body in ({"label": "X9"}, {"label": "O999"}, {"label": 3}, {"lbl": "O0"}):
        r = client.put(f"/api/scene/{vid}/fit/focus", json=body)
        assert r.status_code == 422, (body, r.text)
    for body in ({"kind": "frontier", "t": 0}, {"kind": "frontier", "t": 100000}, {"kind": "empty", "t": 2},
                 {"kind": "frontier", "t": "2"}, {"kind": "frontier", "t": True}):  # fmt: skip
        r = client.put(f"/api/scene/{vid}/fit", json=body)
        assert r.status_code == 422, (body, r.text)
    info = client.get(f"/api/scene/{vid}/fit").json()
    assert info["focus"] == "O0" and not any(k["refit"] for k in info["kinds"])
    assert client.get("/api/scene/nope/fit").status_code == 404
    # a click on an ellipsoid in the scene focuses it
    name = "/clusters/frontier/0"
    wait_for(lambda: owner_of(raw.messages(), name))
    raw.send(click_message(name, 0, owner_of(raw.messages(), name)))
    assert wait_for(lambda: client.get(f"/api/scene/{vid}/fit").json()["focus"] == "F0")
    # focused: the other clusters' voxels are dimmed, the focused one's keep their colour
    plan = _plan_of(env)
    kind = max(("occupied", "frontier"), key=lambda k: sum(e.kind == k for e in plan.ellipsoids))
    label = f"{kind[0].upper()}1"
    mark = raw.mark()
    r = client.put(f"/api/scene/{vid}/fit/focus", json={"label": label})
    assert r.status_code == 200, r.text
    labels = next(f for f in plan.fits if f.kind == kind).labels
    rows = {r["index"]: r for r in client.get(f"/api/scene/{vid}/fit").json()["rows"] if r["kind"] == kind}

    def focused() -> bool:
        clouds = _cluster_clouds(env, mark)
        if kind not in clouds:
            return False
        colors = clouds[kind][1]
        others = colors[labels != 1].astype(float)
        kept = all(tuple(c) == tuple(rows[1]["color"]) for c in colors[labels == 1])
        return kept and len(others) > 0 and bool(np.all(others.min(axis=1) > 150))  # dimmed towards light grey

    assert wait_for(focused)
    client.put(f"/api/scene/{vid}/fit/focus", json={"label": None})


def test_the_viewer_s_state_is_pushed_to_the_page(env: dict[str, Any]) -> None:
    client, sid, vid = env["client"], env["sid"], env["vid"]
    with client.websocket_connect(f"/api/events?session={sid}") as ws:
        assert ws.receive_json()["type"] == "status"
        got: list[dict[str, Any]] = []
        done = threading.Event()

        def read() -> None:
            while not done.is_set():
                m = ws.receive_json()
                got.append(m)
                if m["type"] == "viewer" and m["layers"]["candidates"] is False:
                    done.set()

        reader = threading.Thread(target=read, daemon=True)
        reader.start()
        put = client.put(f"/api/scene/{vid}/layers", json={"candidates": False, "gmm": True}).json()
        assert done.wait(10)
        pushed = [m for m in got if m["type"] == "viewer"][-1]
        assert pushed["viewer"] == vid and pushed["layers"] == put == client.get(f"/api/scene/{vid}").json()["layers"]
        client.put(f"/api/scene/{vid}/layers", json={"candidates": True, "gmm": False})
