"""Fixtures for the workbench API tests: a small, fast planner config and an app per test."""

from __future__ import annotations

import copy
from collections.abc import Callable, Iterator
from pathlib import Path
from typing import Any

import pytest
from apphelpers import BASE_URL, CUBE_OBJ, SMALL, Live, free_port, running_server
from fastapi.testclient import TestClient

from app.main import create_app
from app.settings import AppSettings
from tests.helpers import with_small_costs


@pytest.fixture
def models_dir(tmp_path: Path) -> Path:
    d = tmp_path / "models"
    d.mkdir()
    (d / "cube.obj").write_text(CUBE_OBJ)
    (d / "notes.txt").write_text("not a model")
    return d


@pytest.fixture
def settings(tmp_path: Path, models_dir: Path) -> AppSettings:
    # fault_api: the tests inject faults through the API (a server refuses them without this test flag)
    return with_small_costs(
        AppSettings(viser_port=0, scene=False, models_dir=models_dir, data_dir=tmp_path / "data", fault_api=True)
    )


@pytest.fixture
def client(settings: AppSettings) -> Iterator[TestClient]:
    with TestClient(create_app(settings), base_url=BASE_URL) as c:
        yield c


def _new_session(
    client: TestClient, model: str = "l-block", config: dict[str, Any] | None = None, seed: int = 0
) -> str:
    r = client.post("/api/sessions", json={"model": model, "config": SMALL if config is None else config, "seed": seed})
    assert r.status_code == 201, r.text
    return r.json()["id"]


def _planned_session(client: TestClient, **kw: Any) -> tuple[str, dict[str, Any]]:
    """A session that captured its first view and holds a pending plan: (id, plan response)."""
    sid = _new_session(client, **kw)
    assert client.post(f"/api/sessions/{sid}/capture").status_code == 200
    r = client.post(f"/api/sessions/{sid}/plan")
    assert r.status_code == 200, r.text
    return sid, r.json()


@pytest.fixture
def new_session() -> Callable[..., str]:
    """``new_session(client, model="l-block", config=SMALL, seed=0) -> id``."""
    return _new_session


@pytest.fixture
def planned_session() -> Callable[..., tuple[str, dict[str, Any]]]:
    """``planned_session(client, **kw) -> (id, plan)``: captured once, with a pending plan."""
    return _planned_session


@pytest.fixture
def small_config() -> dict[str, Any]:
    return copy.deepcopy(SMALL)


@pytest.fixture
def cube_obj() -> str:
    return CUBE_OBJ


@pytest.fixture
def live_server(settings: AppSettings) -> Iterator[Live]:
    """A real uvicorn server (URL, app) on a free 127.0.0.1 port, with the test's settings."""
    with running_server(settings.replace(port=free_port())) as live:
        yield live
