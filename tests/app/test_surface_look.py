"""How the surface layer looks in a tab's scene (real viser server, a raw websocket client): the cloud layer,
hidden, hides every cloud chunk (they drew black over the surface in the screenshot); the surface is sent
smooth-shaded (the client computes its vertex normals from the winding) with a consistent, outward winding."""

from __future__ import annotations

from collections.abc import Iterator
from typing import Any

import numpy as np
import pytest
import trimesh
from apphelpers import SMALL
from fastapi.testclient import TestClient

from app.main import create_app
from app.settings import AppSettings
from tests.viewer_wire import RawViewer, wait_for


@pytest.fixture
def scene_client(settings: AppSettings) -> Iterator[TestClient]:
    with TestClient(create_app(settings.replace(scene=True)), base_url="http://127.0.0.1") as c:
        yield c


def test_hidden_cloud_leaves_the_surface_alone_and_the_surface_is_smooth_and_outward(
    scene_client: TestClient,
) -> None:
    c = scene_client
    sid = c.post("/api/sessions", json={"model": "box", "config": SMALL, "seed": 0}).json()["id"]
    r = c.post(f"/api/sessions/{sid}/capture")
    assert r.status_code == 200, r.text
    body = c.post("/api/viewer", json={"session": sid}).json()
    port, ticket = body["port"], body["url"].split("ticket%3D")[1]
    raw = RawViewer(f"ws://127.0.0.1:{port}/?ticket={ticket}", f"http://127.0.0.1:{port}")

    def named(name: str, kind: str) -> list[dict[str, Any]]:
        return [m for m in raw.messages() if m.get("name") == name and kind in m.get("type", "")]

    try:
        vid = body["viewer"]
        assert wait_for(lambda: c.get(f"/api/scene/{vid}").json()["connected"])
        nodes = set(c.get(f"/api/scene/{vid}").json()["nodes"])
        assert "/cloud" in nodes and "/cloud/0" in nodes  # the chunks hang under a group the layer hides
        c.put(f"/api/scene/{vid}/layers", json={"cloud": False, "surface": True})
        assert wait_for(lambda: any(m["visible"] is False for m in named("/cloud", "Visibility")))
        # the chunk keeps its own flag (shown): the group decides
        assert all(m["visible"] for m in named("/cloud/0", "Visibility"))
        assert wait_for(lambda: len(named("/surface", "Mesh")) == 1)
        props = named("/surface", "Mesh")[0]["props"]
        assert props["flat_shading"] is False and props["side"] == "double" and props["material"] == "standard"
        # the layer as sent: one winding all over, facing out of the box (its normals are the client's)
        layer = c.app.state.registry.get(sid).surface.layer  # type: ignore[attr-defined]
        mesh = trimesh.Trimesh(layer.vertices, layer.faces, process=False)
        assert mesh.is_winding_consistent
        centre = np.array([0.0, 0.0, layer.vertices[:, 2].max() / 2])
        outward = np.einsum("ij,ij->i", mesh.face_normals, mesh.triangles_center - centre) > 0
        assert outward.mean() > 0.97
    finally:
        raw.close()
