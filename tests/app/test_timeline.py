"""A session's timeline and recording over REST: each step is the live session as it was after that view (plan id,
best view, scores, voxel counts, the decision), looking changes nothing and is cached, a discard rebuilds it; the
recording zip holds viser's client with the scene embedded, one step per view; ``nbv record`` writes the same from
the journal; the session list is pushed when any session changes state; a viewer's PNG encoder."""

from __future__ import annotations

import io
import json
import zipfile
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import msgspec
import numpy as np
import pytest
import zstandard
from apphelpers import BASE_URL, SMALL, registry_of
from fastapi.testclient import TestClient
from PIL import Image

from app.main import create_app
from app.scene.controller import png_bytes
from app.settings import AppSettings
from nbv.cli import main
from tests.helpers import with_small_costs


def decode_viser(data: bytes) -> tuple[float, list[tuple[float, dict[str, Any]]]]:
    """(durationSeconds, [(time, message)]) of a ``.viser`` file (zstd of msgpack + aligned buffers)."""
    size = int.from_bytes(data[:8], "little")
    inner = zstandard.ZstdDecompressor().decompress(data[8:], max_output_size=size)
    n = int.from_bytes(inner[:8], "little")
    doc = msgspec.msgpack.decode(inner[8 : 8 + n])
    return float(doc["durationSeconds"]), [(float(t), m) for t, m in doc["messages"]]


@pytest.fixture(scope="module")
def scanned(tmp_path_factory: pytest.TempPathFactory) -> Iterator[tuple[TestClient, str, list[dict[str, Any]]]]:
    """A 3-view session (an override at view 1, the planner's choice at view 2, a plan pending after view 3) and,
    per view, what the live session showed then: its status and its candidates."""
    tmp = tmp_path_factory.mktemp("timeline")
    settings = with_small_costs(AppSettings(viser_port=0, scene=False, models_dir=tmp, data_dir=tmp / "data"))
    with TestClient(create_app(settings), base_url=BASE_URL) as client:
        sid = client.post("/api/sessions", json={"model": "l-block", "config": SMALL}).json()["id"]
        assert client.post(f"/api/sessions/{sid}/capture").status_code == 200
        live = []
        for view in (1, 2, 3):
            plan = client.post(f"/api/sessions/{sid}/plan").json()
            live.append(
                {
                    "status": client.get(f"/api/sessions/{sid}").json(),
                    "candidates": client.get(f"/api/sessions/{sid}/candidates").json(),
                }
            )
            if view == 3:
                break
            index = plan["best"]["index"]
            if view == 1:  # an override: an eligible candidate that is not the planner's choice
                index = next(c["index"] for c in live[-1]["candidates"] if c["eligible"] and c["index"] != index)
            r = client.post(f"/api/sessions/{sid}/approve", json={"plan_id": plan["plan_id"], "index": index})
            assert r.status_code == 200, r.text
        yield client, sid, live


def test_each_step_is_the_live_session_after_that_view(scanned) -> None:
    client, sid, live = scanned
    before = client.get(f"/api/sessions/{sid}").json()
    doc = client.get(f"/api/sessions/{sid}/timeline").json()
    assert doc["views"] == 3
    for step, seen in zip(doc["steps"], live, strict=True):
        st = seen["status"]
        assert step["plan_id"] == st["pending_plan"]["plan_id"]
        assert step["best"]["index"] == st["pending_plan"]["best"]["index"]
        assert step["best"]["score"] == pytest.approx(st["pending_plan"]["best"]["score"], rel=1e-9)
        assert step["voxels"] == st["voxels"] and step["points"] == st["points"] and step["coverage"] == st["coverage"]
        scores = client.get(f"/api/sessions/{sid}/timeline/{step['view']}/candidates").json()
        assert [c["score"] for c in scores] == pytest.approx([c["score"] for c in seen["candidates"]], rel=1e-9)
        assert [c["eligible"] for c in scores] == [c["eligible"] for c in seen["candidates"]]
    first, second, third = doc["steps"]
    assert first["decision"]["kind"] == "override" and first["approved"] != first["best"]["index"]
    assert second["decision"]["kind"] == "approve" and second["approved"] == second["best"]["index"]
    assert third["decision"] is None and third["approved"] is None  # its plan is still pending
    assert client.get(f"/api/sessions/{sid}/timeline/2").json() == second
    after = client.get(f"/api/sessions/{sid}").json()
    assert after == before  # looking back changed nothing
    session = registry_of(client).get(sid)
    builds = session.history.builds
    client.get(f"/api/sessions/{sid}/timeline/1")
    assert session.history.builds == builds  # cached: the journal did not grow


def test_a_view_not_taken_is_404(scanned) -> None:
    client, sid, _ = scanned
    for view in (0, 4):
        r = client.get(f"/api/sessions/{sid}/timeline/{view}")
        assert r.status_code == 404 and "views 1 to 3" in r.json()["detail"]
    assert client.get("/api/sessions/nope/timeline").status_code == 404


def test_the_recording_plays_one_step_per_view(scanned, tmp_path: Path) -> None:
    client, sid, _ = scanned
    r = client.get(f"/api/sessions/{sid}/recording")
    assert r.status_code == 200 and r.headers["content-type"] == "application/zip"
    assert f"nbv-{sid}-recording.zip" in r.headers["content-disposition"]
    z = zipfile.ZipFile(io.BytesIO(r.content))
    top = f"nbv-{sid}-recording/"  # one folder: unzipping does not spill files into the current directory
    assert sorted(z.namelist()) == [top + "index.html", top + "scene.viser", top + "steps.json"]
    page = z.read(top + "index.html").decode()
    assert "window.__VISER_EMBED_DATA__=" in page and 'data-testid="recording-steps"' in page
    timeline = client.get(f"/api/sessions/{sid}/timeline").json()["steps"]
    assert json.loads(z.read(top + "steps.json"))["steps"] == timeline
    duration, messages = decode_viser(z.read(top + "scene.viser"))
    assert duration == pytest.approx(3 * 2.0)
    labels = [(t, m["props"]["text"]) for t, m in messages if m.get("name") == "/recording/step" and "props" in m]
    assert [text.split(" · ")[0] for _, text in labels] == ["view 1 of 3", "view 2 of 3", "view 3 of 3"]
    assert [t for t, _ in labels] == [0.0, 2.0, 4.0]
    assert "override" in labels[0][1] and f"best #{timeline[0]['best']['index']}" in labels[0][1]
    frames = {m["name"]: t for t, m in messages if m.get("name", "").endswith("/frustum") and "props" in m}
    assert {k: v for k, v in frames.items() if k.startswith("/views/")} == {
        "/views/1/frustum": 0.0,
        "/views/2/frustum": 2.0,
        "/views/3/frustum": 4.0,
    }
    occupied = [m for t, m in messages if m.get("name") == "/map/occupied" and "points" in m.get("props", {})]
    assert len(occupied) == 3  # each step's own map
    # lit like the live viewers (app/scene/lighting.py): no environment map to prefilter, the hemisphere light
    environment = [m for _, m in messages if m.get("type") == "EnvironmentMapMessage"]
    assert environment and environment[-1]["hdri_data"] is None
    lights = [m for _, m in messages if m.get("type") == "HemisphereLightMessage"]
    assert [m["name"] for m in lights] == ["/lights/hemisphere"] and lights[0]["props"]["intensity"] > 0


def test_nbv_record_writes_the_recording_of_a_journal(scanned, tmp_path: Path, capsys) -> None:
    client, sid, _ = scanned
    directory = registry_of(client).get(sid).journal.directory
    out = tmp_path / "scan.zip"
    assert main(["record", str(directory), "--out", str(out)]) == 0
    assert "3 views" in capsys.readouterr().out
    z = zipfile.ZipFile(out)
    served = client.get(f"/api/sessions/{sid}/timeline").json()["steps"]
    assert json.loads(z.read("scan/steps.json"))["steps"] == served  # replayed in a replay cell: the same plans
    assert main(["record", str(directory), "--out", str(tmp_path / "scan.tar")]) == 2
    assert "FILE.zip" in capsys.readouterr().err
    assert main(["record", str(tmp_path), "--out", str(out)]) == 2


def test_a_discard_rebuilds_the_timeline(tmp_path: Path) -> None:
    settings = with_small_costs(AppSettings(viser_port=0, scene=False, models_dir=tmp_path, data_dir=tmp_path / "data"))
    with TestClient(create_app(settings), base_url=BASE_URL) as client:
        sid = client.post("/api/sessions", json={"model": "two-boxes", "config": SMALL}).json()["id"]
        client.post(f"/api/sessions/{sid}/capture")
        plan = client.post(f"/api/sessions/{sid}/plan").json()
        client.post(f"/api/sessions/{sid}/approve", json={"plan_id": plan["plan_id"], "index": plan["best"]["index"]})
        assert client.get(f"/api/sessions/{sid}/timeline").json()["views"] == 2
        assert client.post(f"/api/sessions/{sid}/discard").status_code == 200
        doc = client.get(f"/api/sessions/{sid}/timeline").json()
        assert doc["views"] == 1 and doc["steps"][0]["plan_id"] == plan["plan_id"]
        assert doc["steps"][0]["decision"] is None  # the view it took was discarded: the plan waits again
        assert registry_of(client).get(sid).history.builds == 2


def test_every_tab_hears_any_session_change_state(client: TestClient, new_session) -> None:
    a, b = new_session(client), new_session(client)
    with client.websocket_connect(f"/api/events?session={a}") as ws:
        assert ws.receive_json()["status"]["id"] == a
        assert client.post(f"/api/sessions/{b}/capture").status_code == 200
        for _ in range(20):
            m = ws.receive_json()
            if m["type"] == "sessions" and m["change"] == "state" and m["session"]["iteration"] == 1:
                break
        else:
            raise AssertionError("no pushed state of the other session")
        assert m["id"] == b and m["session"]["state"] == "ready"


def test_png_bytes_puts_a_transparent_view_on_white() -> None:
    rgba = np.zeros((4, 6, 4), dtype=np.uint8)
    rgba[1, 2] = (200, 10, 30, 255)
    out = np.asarray(Image.open(io.BytesIO(png_bytes(rgba))))
    assert out.shape == (4, 6, 3) and tuple(out[1, 2]) == (200, 10, 30) and tuple(out[0, 0]) == (255, 255, 255)
    with pytest.raises(ValueError, match="expected"):
        png_bytes(np.zeros((4, 6), dtype=np.uint8))
