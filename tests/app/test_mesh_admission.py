"""Degenerate meshes and parser bombs through the API: 422 / 413 at upload and at create, naming the problem."""

from __future__ import annotations

from pathlib import Path

import pytest
from apphelpers import SMALL
from fastapi.testclient import TestClient

from tests.mesh_bombs import instancing_glb

OUTLIER = "v 0 0 0\nv 0.01 0 0\nv 0 0.01 0\nv 0 0 0.01\nv 1e30 0 0\nf 1 2 3\nf 1 2 4\nf 1 3 4\nf 2 3 4\nf 1 2 5\n"
ZERO_AREA = "v 0 0 0\nv 1 0 0\nv 2 0 0\nv 3 0 0\nf 1 2 3\nf 2 3 4\n"
OVERFLOW = "v -1e308 0 0\nv 1e308 0 0\nv 0 1e308 0\nf 1 2 3\n"
SHEET = "v 0 0 0\nv 0.1 0 0\nv 0.1 0.1 0\nv 0 0.1 0\nf 1 2 3\nf 1 3 4\n"  # y-up file: stands on the plate


@pytest.mark.parametrize(
    ("text", "message"),
    [(OUTLIER, "far outlier vertex"), (ZERO_AREA, "zero total surface area"), (OVERFLOW, "extent overflows")],
)
def test_a_degenerate_mesh_is_refused_at_upload_and_at_create(
    client: TestClient, models_dir: Path, text: str, message: str
) -> None:
    r = client.post("/api/models", files={"file": ("bad.obj", text.encode())})
    assert r.status_code == 422 and message in r.json()["detail"], r.text
    (models_dir / "bad.obj").write_text(text)
    r = client.post("/api/sessions", json={"model": "bad.obj", "config": SMALL})
    assert r.status_code == 422 and message in r.json()["detail"] and "bad.obj" in r.json()["detail"], r.text
    assert client.get("/api/sessions").json() == []


def test_a_standing_sheet_is_accepted(client: TestClient) -> None:
    r = client.post("/api/models", files={"file": ("sheet.obj", SHEET.encode())})
    assert r.status_code == 201, r.text
    r = client.post("/api/sessions", json={"model": r.json()["name"], "config": SMALL})
    assert r.status_code == 201, r.text


def test_an_instancing_glb_is_refused_at_upload(client: TestClient) -> None:
    r = client.post("/api/models", files={"file": ("bomb.glb", instancing_glb(1_500))})
    assert r.status_code == 413 and "1500 mesh instances" in r.json()["detail"], r.text
