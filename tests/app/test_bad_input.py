"""Bad input is refused with a clear message and nothing changes: uploads, frames, parameters, overrides, unknowns."""

from __future__ import annotations

import json
import re
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from apphelpers import BASE_URL, SMALL, registry_of
from fastapi.testclient import TestClient

from app.main import create_app
from app.settings import AppSettings
from devices.ply import write_ply
from planner import Pose

CUBE_FACES = (
    "f 1 3 2\nf 1 4 3\nf 5 6 7\nf 5 7 8\nf 1 2 6\nf 1 6 5\nf 2 3 7\nf 2 7 6\nf 3 4 8\nf 3 8 7\nf 4 1 5\nf 4 5 8\n"
)
CUBE_VERTS = "v 0 0 0\nv 1 0 0\nv 1 1 0\nv 0 1 0\nv 0 0 1\nv 1 0 1\nv 1 1 1\nv 0 1 1\n"


def detail(r) -> str:
    body = r.json()
    assert set(body) == {"detail"}, body
    return str(body["detail"])


def state(client: TestClient, sid: str) -> dict[str, Any]:
    st = client.get(f"/api/sessions/{sid}").json()
    return {k: st[k] for k in ("state", "iteration", "moves", "points", "voxels", "pending_plan")}


# ---------------------------------------------------------------------- uploads


@pytest.mark.parametrize(
    ("name", "data", "status", "message"),
    [
        ("junk.obj", b"this is not a mesh at all", 422, "empty mesh"),
        ("random.stl", bytes(range(256)) * 4, 422, "upload 'random.stl'"),
        ("empty.obj", b"", 422, "empty file"),
        ("points.obj", CUBE_VERTS.encode(), 422, "point cloud"),
        ("nan.obj", ("v nan 0 0\n" + CUBE_VERTS[8:] + CUBE_FACES).encode(), 422, "non-finite"),
        ("inf.obj", (CUBE_VERTS.replace("v 1 1 1", "v 1 inf 1") + CUBE_FACES).encode(), 422, "non-finite"),
        ("flat.obj", b"v 0 0 0\nv 0 0 0\nv 0 0 0\nf 1 2 3\n", 422, "degenerate"),
        ("virus.exe", b"MZ", 422, "unsupported file type"),
        ("big.obj", (CUBE_VERTS + CUBE_FACES + "# padding\n" * 400).encode(), 413, "over the limit"),
    ],
)
def test_bad_uploads_are_refused_and_nothing_is_kept(
    tmp_path: Path, models_dir: Path, name: str, data: bytes, status: int, message: str
) -> None:
    settings = AppSettings(scene=False, models_dir=models_dir, data_dir=tmp_path / "d", max_upload_bytes=3000)
    with TestClient(create_app(settings), base_url=BASE_URL) as client:
        models = client.get("/api/models").json()
        r = client.post("/api/models", files={"file": (name, data, "application/octet-stream")})
        assert r.status_code == status, r.text
        assert message in detail(r)
        assert str(tmp_path) not in detail(r)  # no server path in the message
        assert client.get("/api/models").json() == models
        uploads = tmp_path / "d" / "uploads"
        assert not uploads.exists() or list(uploads.iterdir()) == []


def test_an_oversized_upload_is_refused_before_it_is_read(tmp_path: Path, models_dir: Path) -> None:
    settings = AppSettings(scene=False, models_dir=models_dir, data_dir=tmp_path / "d", max_upload_bytes=3000)
    with TestClient(create_app(settings), base_url=BASE_URL) as client:
        read = []

        def body():  # a generator body: the server must answer 413 from Content-Length, not read 10 MB
            for _ in range(160):
                read.append(1)
                yield b"x" * 65536

        headers = {"content-type": "multipart/form-data; boundary=b", "content-length": str(160 * 65536)}
        r = client.post("/api/models", content=body(), headers=headers)
        assert r.status_code == 413 and "over the limit" in detail(r)
        r = client.post(
            "/api/sessions", content=b"{" + b" " * 2_000_000 + b"}", headers={"content-type": "application/json"}
        )
        assert r.status_code == 413
        assert client.get("/api/sessions").json() == []


# ---------------------------------------------------------------------- frames


def write_view(folder: Path, name: str, points: np.ndarray, pose: Pose) -> None:
    write_ply(folder / f"{name}.ply", points)
    (folder / f"{name}.json").write_text(json.dumps({"T_world_camera": pose.to_dict()}))


@pytest.mark.parametrize(("case", "message"), [("nan", "non-finite"), ("inf", "non-finite"), ("empty", "empty view")])
def test_recordings_with_bad_frames_are_refused(
    client: TestClient, settings: AppSettings, case: str, message: str
) -> None:
    folder = settings.data_dir / "recordings" / f"rig-{case}"
    folder.mkdir(parents=True)
    (folder / "intrinsics.json").write_text(json.dumps(dict(width=64, height=48, fx=60, fy=60, cx=31.5, cy=23.5)))
    pose = Pose.look_at([0.5, 0.0, 0.3], [0.0, 0.0, 0.05])
    rng = np.random.default_rng(0)
    points = rng.uniform(-0.05, 0.05, (200, 3)) + np.array([0.0, 0.0, 0.05])
    write_view(folder, "a", points, pose)
    bad = points.copy()
    if case == "nan":
        bad[3, 1] = np.nan
    elif case == "inf":
        bad[4, 0] = -np.inf
    else:
        bad = pose.apply(np.array([[0.0, 0.0, -0.3]]))  # behind the camera
    write_view(folder, "b", bad, pose)
    assert f"rig-{case}" in client.get("/api/recordings").json()
    r = client.post("/api/sessions", json={"source": {"kind": "replay", "recording": f"rig-{case}"}})
    assert r.status_code == 422 and message in detail(r) and "b.ply" in detail(r)
    assert str(settings.data_dir) not in detail(r)
    assert client.get("/api/sessions").json() == []


@pytest.mark.parametrize(("kind", "message"), [("nan_frame", "non-finite"), ("empty_frame", "empty frame")])
def test_a_camera_returning_nan_or_nothing_changes_nothing(client: TestClient, kind: str, message: str) -> None:
    sid = client.post(
        "/api/sessions", json={"config": SMALL, "faults": {"schedule": [{"kind": kind, "at": 2}]}}
    ).json()["id"]
    client.post(f"/api/sessions/{sid}/capture")
    plan = client.post(f"/api/sessions/{sid}/plan").json()
    before = state(client, sid)
    cloud = client.get(f"/api/sessions/{sid}/cloud.ply").content
    index = plan["best"]["index"]
    if kind == "empty_frame":  # the planner's choice would fall back to the next candidate: a person's choice
        cands = client.get(f"/api/sessions/{sid}/candidates").json()
        index = sorted((c for c in cands if c["eligible"]), key=lambda c: -c["score"])[1]["index"]
    r = client.post(f"/api/sessions/{sid}/approve", json={"plan_id": plan["plan_id"], "index": index})
    assert r.status_code == 503 and "frame rejected" in detail(r) and message in detail(r)
    after = state(client, sid)
    assert after["state"] == "error" and after["moves"] == before["moves"] + 1
    assert {k: after[k] for k in ("iteration", "points", "voxels", "pending_plan")} == {
        k: before[k] for k in ("iteration", "points", "voxels", "pending_plan")
    }
    assert client.get(f"/api/sessions/{sid}/cloud.ply").content == cloud


def test_a_damaged_journaled_frame_is_left_out_on_resume(settings: AppSettings) -> None:
    with TestClient(create_app(settings), base_url=BASE_URL) as a:
        sid = a.post("/api/sessions", json={"config": SMALL}).json()["id"]
        a.post(f"/api/sessions/{sid}/capture")
    frame = settings.data_dir / "sessions" / sid / "frames" / "000001.npz"
    data = dict(np.load(frame))
    data["depth"][10, 10] = np.nan
    np.savez(frame, **data)
    with TestClient(create_app(settings), base_url=BASE_URL) as b:
        r = b.post(f"/api/sessions/{sid}/resume")  # resumes up to the damage: here, before the first view
        assert r.status_code == 200 and "checksum mismatch" in r.json()["dropped"][0], r.text
        assert (r.json()["session"]["state"], r.json()["session"]["iteration"]) == ("new", 0)


# ---------------------------------------------------------------------- parameters


@pytest.mark.parametrize(
    ("body", "message"),
    [
        ({"config": {"voxel": {"resolution": 1e-6}}}, "voxel.resolution must be in"),
        ({"config": {"voxel": {"resolution": 0.002, "max_extent": 3.0}}}, "voxels per axis"),
        ({"config": {"candidates": {"count": 1_000_000}}}, "candidates.count"),
        ({"config": {"cluster": {"t_max": 100_000}}}, "cluster.t_max"),
        ({"config": {"termination": {"max_views": 10**6}}}, "termination.max_views"),
        ({"config": {"voxel": {"resolution": float("inf")}}}, None),
        ({"config": {"voxel": {"resolution": True}}}, "resolution"),
        ({"seed": 2**40}, None),
        ({"model": "x" * 500}, None),
        ({"source": {"kind": "replay"}}, None),
        ({"source": {"kind": "replay", "recording": "a", "session": "0123abcd"}}, None),
        ({"source": {"kind": "sim", "recording": "a"}}, None),
        ({"source": {"kind": "replay", "session": "../../x"}}, None),
        ({"faults": {"arm_halfway": -0.1}}, "faults.arm_halfway"),
    ],
)
def test_out_of_range_session_parameters_are_422(client: TestClient, body: dict, message: str | None) -> None:
    r = client.post("/api/sessions", content=json.dumps(body), headers={"content-type": "application/json"})
    assert r.status_code == 422, r.text
    if message is not None:
        assert message in detail(r)
    assert client.get("/api/sessions").json() == []


def test_out_of_range_requests_on_a_session_are_422(client: TestClient, planned_session) -> None:
    sid, _ = planned_session(client)
    before = state(client, sid)
    for method, path, body in [
        ("post", "/step", {"count": 0}),
        ("post", "/step", {"count": 101}),
        ("post", "/auto", {"count": -3}),
        ("put", "/selection", {"index": -1}),
        ("patch", "/config", {"voxel": {"resolution": 0.05}}),
        ("patch", "/config", {"candidates": {"count": 0}}),
        ("patch", "/config", {"candidates": {"count": 10**7}}),
        ("patch", "/config", {"termination": {"bogus": 1}}),
        ("patch", "/config", {"termination": 3}),
        ("put", "/custom_pose", {"pose": {"position": [0, 0, float("inf")], "wxyz": [1, 0, 0, 0]}}),
        ("put", "/custom_pose", {"pose": {"position": [0, 0, float("nan")], "wxyz": [1, 0, 0, 0]}}),
    ]:
        raw = json.dumps(body)  # allows NaN / Infinity, which a strict encoder would refuse to send
        r = client.request(
            method.upper(), f"/api/sessions/{sid}{path}", content=raw, headers={"content-type": "application/json"}
        )
        assert r.status_code == 422, (path, body, r.text)
    assert state(client, sid) == before


# ---------------------------------------------------------------------- overrides


@pytest.mark.parametrize(
    ("position", "message"),
    [
        ([0.0, 0.0, 0.06], "inside the object|collision:.*:object"),  # the L-block's middle: the arm hits it first
        ([-0.02, 0.0, 0.28], "too close to the object"),  # a few cm above its top
        ([0.1, 0.0, -0.2], "unreachable"),  # below the plate
        ([3.0, 0.0, 0.5], "unreachable"),  # out of the arm's reach
    ],
)
def test_an_override_inside_the_object_or_unreachable_is_refused(
    client: TestClient, planned_session, position: list[float], message: str
) -> None:
    sid, plan = planned_session(client)
    wb = registry_of(client).get(sid)
    pose = Pose.look_at(position, [0.0, 0.0, 0.08] if position[:2] != [0.0, 0.0] else [0.1, 0.0, 0.0]).to_dict()
    before, arm_moves = state(client, sid), wb.cell.arm.moves
    custom = client.put(f"/api/sessions/{sid}/custom_pose", json={"pose": pose}).json()
    assert custom["reachable"] is False and re.search(message, custom["reason"])
    r = client.post(f"/api/sessions/{sid}/approve", json={"plan_id": plan["plan_id"], "pose": pose})
    assert r.status_code == 422 and re.search(message, detail(r))
    assert state(client, sid) == before and wb.cell.arm.moves == arm_moves  # nothing moved


# ---------------------------------------------------------------------- unknowns and order


@pytest.mark.parametrize(
    ("method", "path", "body"),
    [
        ("post", "/resume", None),
        ("post", "/retry", None),
        ("patch", "/config", {"termination": {"max_views": 3}}),
        ("post", "/faults", {"kind": "capture_failure"}),
        ("put", "/selection", {"index": 0}),
        ("put", "/custom_pose", {"pose": {"position": [0.3, 0, 0.3], "wxyz": [1, 0, 0, 0]}}),
        ("post", "/approve", {"plan_id": "x", "index": 0}),
    ],
)
def test_unknown_sessions_are_404_on_every_route(client: TestClient, method: str, path: str, body: Any) -> None:
    r = client.request(method.upper(), f"/api/sessions/0000aaaa{path}", json=body)
    assert r.status_code == 404 and "0000aaaa" in detail(r)


def test_nothing_before_the_first_frame(client: TestClient, new_session) -> None:
    sid = new_session(client)
    for path in ("/plan", "/step", "/auto"):
        r = client.post(f"/api/sessions/{sid}{path}")
        assert r.status_code == 409 and "capture first" in detail(r)
    for path in ("/candidates", "/candidates/0", "/candidates/0/projection.png"):
        r = client.get(f"/api/sessions/{sid}{path}")
        assert r.status_code == 409 and "no plan yet" in detail(r)
    assert client.post(f"/api/sessions/{sid}/retry").status_code == 409
    assert state(client, sid)["state"] == "new" and state(client, sid)["moves"] == 0


def test_an_overflowing_quaternion_keeps_its_direction(client: TestClient, planned_session) -> None:
    """A quaternion whose squares overflow (``[1e200] * 4``, the best view's scaled by 1e300) is the same rotation
    as its unit quaternion: the custom pose and the approved view are that rotation, never identity."""
    sid, plan = planned_session(client)
    best = Pose.from_dict(plan["best"]["pose"])
    position = best.translation.tolist()
    r = client.put(f"/api/sessions/{sid}/custom_pose", json={"pose": {"position": position, "wxyz": [1e200] * 4}})
    assert r.status_code == 200, r.text
    assert np.allclose(r.json()["pose"]["wxyz"], [0.5, 0.5, 0.5, 0.5])
    huge = [float(c) * 1e300 for c in best.wxyz]  # the best view's rotation, every square overflows
    r = client.post(
        f"/api/sessions/{sid}/approve", json={"plan_id": plan["plan_id"], "pose": {"position": position, "wxyz": huge}}
    )
    assert r.status_code == 200, r.text
    decision = client.get(f"/api/sessions/{sid}/export").json()["decisions"][-1]
    assert np.allclose(decision["pose"]["wxyz"], best.wxyz, atol=1e-9)  # journaled as approved
    wb = registry_of(client).get(sid)
    assert np.allclose(wb.record.iterations[-1]["pose"]["wxyz"], best.wxyz, atol=1e-6)  # the view taken there
    r = client.put(f"/api/sessions/{sid}/custom_pose", json={"pose": {"position": position, "wxyz": [0.0] * 4}})
    assert r.status_code == 422
