"""The first screen's 3D view of no session (``POST /api/viewer/preview``): the simulated cell and the server's
default object drawn into each tab's own scene, the geometry built once and shared, no session created, nothing
journaled; real viser server, raw websocket clients."""

from __future__ import annotations

import dataclasses
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import numpy as np
import pytest
import trimesh
from fastapi.testclient import TestClient

from app.main import create_app
from app.scene.preview import PREVIEW_KEY, PREVIEW_TRIANGLES, build_geometry
from app.settings import AppSettings
from tests.viewer_wire import RawViewer, session_nodes, wait_for
from workbench.journal.store import list_journals
from workbench.sources.catalog import load_model


@pytest.fixture
def scene_client(settings: AppSettings) -> Iterator[TestClient]:
    with TestClient(create_app(settings.replace(scene=True)), base_url="http://127.0.0.1") as c:
        yield c


def open_preview(client: TestClient) -> tuple[dict[str, Any], RawViewer]:
    v = client.post("/api/viewer/preview")
    assert v.status_code == 201, v.text
    body = v.json()
    ticket = body["url"].split("ticket%3D")[1]
    port = body["port"]
    return body, RawViewer(f"ws://127.0.0.1:{port}/?ticket={ticket}", f"http://127.0.0.1:{port}")


def names(messages: list[dict[str, Any]]) -> set[str]:
    return {m["name"] for m in messages if isinstance(m.get("name"), str)}


def object_message(messages: list[dict[str, Any]]) -> dict[str, Any]:
    return next(m for m in messages if m.get("name") == "/preview/object" and "props" in m)


def test_two_tabs_see_the_cell_and_the_default_object_built_once_and_no_session(
    scene_client: TestClient, settings: AppSettings
) -> None:
    previews = scene_client.app.state.preview_views  # type: ignore[attr-defined]
    (a, raw_a), (b, raw_b) = open_preview(scene_client), open_preview(scene_client)
    try:
        assert a["session"] == b["session"] == PREVIEW_KEY and a["viewer"] != b["viewer"]
        for raw in (raw_a, raw_b):
            assert wait_for(lambda raw=raw: {"/preview/object", "/preview/turntable"} <= names(raw.messages()))
            assert wait_for(lambda raw=raw: any(n.startswith("/robot/arm/") for n in names(raw.messages())))
            got = raw.messages()
            assert session_nodes(got) == set()  # nothing a session draws
            label = next(m for m in got if m.get("name") == "/preview/label")
            assert settings.devices.model in label["props"]["text"]
        # the object's mesh is the placed default model (as a session on it holds it; this one under the budget)
        mesh = load_model(settings, settings.devices.model)
        sent = object_message(raw_a.messages())["props"]
        assert len(mesh.faces) < PREVIEW_TRIANGLES
        assert sent["faces"]["nbytes"] == np.asarray(mesh.faces, np.uint32).nbytes
        assert sent["vertices"]["nbytes"] == np.asarray(mesh.vertices, np.float32).nbytes
        assert wait_for(lambda: previews.tabs() == 2) and previews.builds == 1
        assert scene_client.get("/api/sessions").json() == []
        assert list_journals(settings.data_dir) == []
    finally:
        raw_a.close()
        raw_b.close()
    assert wait_for(lambda: previews.tabs() == 0)


def test_the_geometry_is_the_demo_cell_s(scene_client: TestClient, settings: AppSettings) -> None:
    g = scene_client.app.state.preview_views.geometry()  # type: ignore[attr-defined]
    assert g.model == settings.devices.model and g.plate_radius == settings.devices.cell.plate_radius
    assert g.arm is not None and g.q is not None and g.q.shape == (g.arm.nq,) and np.all(np.isfinite(g.q))
    assert g.mount_xy is not None and np.hypot(*g.mount_xy) > 0.1  # the arm stands off the plate's middle
    assert g.vertices.dtype == np.float32 and g.faces.dtype == np.uint32 and g.faces.max() < len(g.vertices)
    assert g.vertices[:, 2].min() >= -1e-3  # on the plate, not through it


def test_a_large_default_model_is_simplified_to_the_budget(settings: AppSettings, models_dir: Path) -> None:
    big = trimesh.creation.icosphere(subdivisions=6, radius=1.0)  # 81 920 faces
    big.export(models_dir / "big-ball.ply")
    mine = settings.replace(devices=dataclasses.replace(settings.devices, model="big-ball.ply"))
    g = build_geometry(mine)
    placed = load_model(mine, "big-ball.ply")
    assert len(placed.faces) == 81_920 and PREVIEW_TRIANGLES * 0.9 <= len(g.faces) <= PREVIEW_TRIANGLES
    lo, hi = g.vertices.min(axis=0), g.vertices.max(axis=0)  # the same placed object, coarser
    assert np.allclose(lo, placed.bounds[0], atol=0.01) and np.allclose(hi, placed.bounds[1], atol=0.01)


def test_preview_is_409_without_a_scene(client: TestClient) -> None:
    assert client.post("/api/viewer/preview").status_code == 409
