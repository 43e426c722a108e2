"""The reconstructed surface of a session, through the API: built in the session's worker after each view,
served as PLY / OBJ / GLB (loaded back with trimesh), scored per view, and the same after a resume or a discard
(rebuilt from the journal)."""

from __future__ import annotations

import io
from collections.abc import Iterator
from contextlib import contextmanager

import numpy as np
import pytest
import trimesh
from apphelpers import BASE_URL, SMALL
from fastapi.testclient import TestClient

from app.main import create_app
from app.settings import AppSettings


@contextmanager
def server(settings: AppSettings) -> Iterator[TestClient]:
    with TestClient(create_app(settings), base_url=BASE_URL) as c:
        yield c


def take_views(client: TestClient, sid: str, views: int) -> None:
    assert client.post(f"/api/sessions/{sid}/capture").status_code == 200
    for _ in range(views - 1):
        plan = client.post(f"/api/sessions/{sid}/plan").json()
        body = {"plan_id": plan["plan_id"], "index": plan["best"]["index"]}
        assert client.post(f"/api/sessions/{sid}/approve", json=body).status_code == 200


def surface_of(client: TestClient, sid: str, fmt: str = "ply") -> trimesh.Trimesh:
    r = client.get(f"/api/sessions/{sid}/surface.ply", params={"format": fmt})
    assert r.status_code == 200, r.text
    assert f"surface.{fmt}" in r.headers["content-disposition"]
    loaded = trimesh.load(io.BytesIO(r.content), file_type=fmt, force="mesh", process=False)
    assert isinstance(loaded, trimesh.Trimesh)
    return loaded


def test_surface_follows_the_views_and_serves_three_formats(settings: AppSettings) -> None:
    with server(settings) as c:
        sid = c.post("/api/sessions", json={"model": "box", "config": SMALL, "seed": 1}).json()["id"]
        r = c.get(f"/api/sessions/{sid}/surface.ply")
        assert r.status_code == 409 and "no surface yet" in r.json()["detail"]
        assert c.get("/api/sessions/nope/surface.ply").status_code == 404
        take_views(c, sid, 2)
        ply = surface_of(c, sid)
        assert len(ply.faces) > 1000 and ply.bounds[0][2] >= 0.0  # the plate is cut away
        for fmt in ("obj", "glb"):
            other = surface_of(c, sid, fmt)
            assert len(other.faces) == len(ply.faces)
            np.testing.assert_allclose(np.sort(other.vertices, axis=0), np.sort(ply.vertices, axis=0), atol=1e-6)
        assert c.get(f"/api/sessions/{sid}/surface.ply", params={"format": "stl"}).status_code == 422
        # scored per view against the session's mesh (the built-in box), in the metrics and the export
        points = c.get(f"/api/sessions/{sid}/metrics").json()["iterations"]
        scores = [p["surface_fscore_5mm"] for p in points]
        assert len(scores) == 2 and all(0.2 < f <= 1.0 for f in scores) and scores[1] >= scores[0] - 0.02
        block = c.get(f"/api/sessions/{sid}/export").json()["surface"]
        assert block["fscore_5mm"] == scores[-1] and block["triangles"] == len(ply.faces)
        assert block["views"] == 2 and block["error"] is None and 0 < block["layer_triangles"] <= 15_000
        assert 0.9 <= block["precision_5mm"] <= 1.0


@pytest.mark.slow
@pytest.mark.parametrize("workers", [True, False])
def test_resumed_and_discarded_sessions_rebuild_the_same_surface(settings: AppSettings, workers: bool) -> None:
    settings = settings.replace(workers=workers)
    with server(settings) as a:
        sid = a.post("/api/sessions", json={"model": "box", "config": SMALL, "seed": 2}).json()["id"]
        take_views(a, sid, 2)
        two = a.get(f"/api/sessions/{sid}/surface.ply").content
        take_views_more = a.post(f"/api/sessions/{sid}/plan").json()
        body = {"plan_id": take_views_more["plan_id"], "index": take_views_more["best"]["index"]}
        assert a.post(f"/api/sessions/{sid}/approve", json=body).status_code == 200
        three = a.get(f"/api/sessions/{sid}/surface.ply").content
        live_block = a.get(f"/api/sessions/{sid}/export").json()["surface"]
        assert three != two
    with server(settings) as b:
        assert b.post(f"/api/sessions/{sid}/resume").status_code == 200
        assert b.get(f"/api/sessions/{sid}/surface.ply").content == three  # byte for byte
        resumed = b.get(f"/api/sessions/{sid}/export").json()["surface"]
        assert {k: v for k, v in resumed.items() if k != "seconds"} == {
            k: v for k, v in live_block.items() if k != "seconds"
        }
        assert b.post(f"/api/sessions/{sid}/discard").status_code == 200
        assert b.get(f"/api/sessions/{sid}/surface.ply").content == two
        # the next view after the discard continues from the rebuilt surface
        plan = b.post(f"/api/sessions/{sid}/plan").json()
        body = {"plan_id": plan["plan_id"], "index": plan["best"]["index"]}
        assert b.post(f"/api/sessions/{sid}/approve", json=body).status_code == 200
        assert b.get(f"/api/sessions/{sid}/export").json()["surface"]["views"] == 3
