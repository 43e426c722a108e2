"""Recorded views from another rig (PLY + pose JSON per view) enter the workbench as a replay source."""

from __future__ import annotations

import json
from typing import Any

import numpy as np
import pytest
from apphelpers import SMALL
from fastapi.testclient import TestClient

from app.settings import AppSettings
from devices.builtins import make_builtin
from devices.ply import write_ply
from devices.sim import make_sim_cell
from planner import Pose


def record(settings: AppSettings, name: str, azimuths: list[float]) -> list[int]:
    """A recording folder rendered by the simulated cell, points in the camera frame; returns points per view."""
    folder = settings.data_dir / "recordings" / name
    folder.mkdir(parents=True)
    cell = make_sim_cell(make_builtin("two-boxes", 0.2))
    k = cell.intrinsics
    (folder / "intrinsics.json").write_text(
        json.dumps(dict(width=k.width, height=k.height, fx=k.fx, fy=k.fy, cx=k.cx, cy=k.cy))
    )
    counts = []
    for i, a in enumerate(azimuths):
        pose = Pose.look_at([0.5 * np.cos(a), 0.5 * np.sin(a), 0.3], [0.0, 0.0, 0.08])
        cell.move_to(pose)
        frame = cell.capture()
        write_ply(folder / f"view_{i:03d}.ply", frame.points_camera)
        meta = {"T_world_camera": frame.T_world_camera.to_dict(), "points_frame": "camera"}
        (folder / f"view_{i:03d}.json").write_text(json.dumps(meta))
        counts.append(len(frame.points_camera))
    return counts


def test_a_recording_is_scanned_view_by_view(client: TestClient, settings: AppSettings) -> None:
    record(settings, "rig-a", [3.0, 1.0, -1.2])
    assert client.get("/api/recordings").json() == ["rig-a"]
    body = {"config": SMALL, "source": {"kind": "replay", "recording": "rig-a"}}
    sid = client.post("/api/sessions", json=body).json()["id"]
    st = client.post(f"/api/sessions/{sid}/capture").json()
    assert (st["model"], st["source"], st["iteration"], st["coverage"]) == ("replay:rig-a", "replay", 1, None)
    assert st["points"] > 1000 and st["voxels"]["occupied"] > 20
    plan = client.post(f"/api/sessions/{sid}/plan").json()
    assert plan["best"] is not None and plan["n_eligible"] > 0
    st = client.post(f"/api/sessions/{sid}/approve", json={"plan_id": plan["plan_id"], "index": plan["best"]["index"]})
    assert st.status_code == 200 and st.json()["iteration"] == 2
    views = client.get(f"/api/sessions/{sid}/export").json()["iterations"]
    recorded = Pose.from_dict(
        json.loads((settings.data_dir / "recordings/rig-a/view_001.json").read_text())["T_world_camera"]
    )
    assert np.allclose(views[1]["pose"]["position"], recorded.translation, atol=0.03)  # the recorded view (ICP-refined)
    assert client.post(f"/api/sessions/{sid}/step").json()["iteration"] == 3
    r = client.post(f"/api/sessions/{sid}/step")
    assert r.status_code == 503 and "all 3 recorded frames" in r.json()["detail"]
    assert client.get(f"/api/sessions/{sid}").json()["iteration"] == 3  # the map is kept


def test_nearest_mode_plays_the_view_nearest_the_approved_pose(client: TestClient, settings: AppSettings) -> None:
    azimuths = list(np.linspace(-np.pi, np.pi, 12, endpoint=False))
    record(settings, "ring", azimuths)
    body = {"config": SMALL, "source": {"kind": "replay", "recording": "ring", "mode": "nearest"}}
    sid = client.post("/api/sessions", json=body).json()["id"]
    client.post(f"/api/sessions/{sid}/capture")
    plan = client.post(f"/api/sessions/{sid}/plan").json()
    target = np.array(plan["best"]["pose"]["position"])
    client.post(f"/api/sessions/{sid}/approve", json={"plan_id": plan["plan_id"], "index": plan["best"]["index"]})
    got = np.array(client.get(f"/api/sessions/{sid}/export").json()["iterations"][1]["pose"]["position"])
    ring = np.array([[0.5 * np.cos(a), 0.5 * np.sin(a), 0.3] for a in azimuths])
    nearest = ring[np.argmin(np.linalg.norm(ring - target, axis=1))]
    assert np.linalg.norm(got - nearest) < 0.03


def test_a_resumed_replay_session_continues_with_the_next_recorded_view(settings: AppSettings) -> None:
    from apphelpers import BASE_URL

    from app.main import create_app

    record(settings, "rig-b", [3.0, 1.0, -1.2])
    body = {"config": SMALL, "source": {"kind": "replay", "recording": "rig-b"}}
    with TestClient(create_app(settings), base_url=BASE_URL) as a:
        sid = a.post("/api/sessions", json=body).json()["id"]
        a.post(f"/api/sessions/{sid}/capture")
        before = a.post(f"/api/sessions/{sid}/step").json()
    with TestClient(create_app(settings), base_url=BASE_URL) as b:
        r = b.post(f"/api/sessions/{sid}/resume").json()
        assert r["verified"] and r["session"]["points"] == before["points"]
        st = b.post(f"/api/sessions/{sid}/step").json()
        assert st["iteration"] == 3  # the third recorded view, not the first again

        r = b.post(f"/api/sessions/{sid}/step")
        assert r.status_code == 503 and "all 3 recorded frames" in r.json()["detail"]


@pytest.mark.slow
def test_a_recorded_set_is_a_source_whose_views_are_the_only_candidates(
    client: TestClient, settings: AppSettings
) -> None:
    from devices.config import CellConfig
    from devices.recorded import write_view_folder

    mesh = make_builtin("two-boxes", 0.2)
    cell = make_sim_cell(mesh, cell_config=CellConfig(kinematics="reach_sphere"))
    frames = []
    for a in (0.3, 2.4, -1.9, 1.2):
        cell.move_to(Pose.look_at([0.5 * np.cos(a), 0.5 * np.sin(a), 0.3], [0.0, 0.0, 0.08]))
        frames.append(cell.capture())
    write_view_folder(settings.data_dir / "recorded" / "boxes", frames, reference=mesh)
    assert client.get("/api/recorded").json() == ["boxes"]
    body = {"config": SMALL, "source": {"kind": "recorded", "recorded": "boxes"}}
    sid = client.post("/api/sessions", json=body).json()["id"]
    st = client.post(f"/api/sessions/{sid}/capture").json()
    assert (st["model"], st["source"], st["iteration"]) == ("recorded:boxes", "recorded", 1)
    assert 0.1 < st["coverage"] < 0.9  # scored against the set's reference mesh
    plan = client.post(f"/api/sessions/{sid}/plan").json()
    assert plan["n_candidates"] == 4  # the recorded views, not the hemisphere's candidates
    assert 1 <= plan["n_eligible"] <= 3 and plan["best"]["index"] != 0  # the view taken is not offered again
    st = client.post(f"/api/sessions/{sid}/approve", json={"plan_id": plan["plan_id"], "index": plan["best"]["index"]})
    assert st.status_code == 200 and st.json()["iteration"] == 2
    got = np.array(client.get(f"/api/sessions/{sid}/export").json()["iterations"][1]["pose"]["position"])
    recorded = np.array([f.T_world_camera.translation for f in frames[1:]])
    assert np.min(np.linalg.norm(recorded - got, axis=1)) < 0.01  # a recorded view (ICP-refined)
    bad = {"config": SMALL, "source": {"kind": "recorded", "recorded": "nope"}}
    assert client.post("/api/sessions", json=bad).status_code == 404
    assert client.post("/api/sessions", json={"source": {"kind": "recorded"}}).status_code == 422


def recorded_boxes(settings: AppSettings) -> list[Pose]:
    """A recorded set ``data_dir/recorded/boxes``: four views of two boxes in our folder format, the last one's pose
    put under the plate top (as the Stanford bunny's chin scan is: the set has no plate); returns their poses."""
    from devices.config import CellConfig
    from devices.recorded import write_view_folder

    mesh = make_builtin("two-boxes", 0.2)
    cell = make_sim_cell(mesh, cell_config=CellConfig(kinematics="reach_sphere"))
    frames = []
    for a in (0.3, 2.4, -1.9, 1.2):
        cell.move_to(Pose.look_at([0.5 * np.cos(a), 0.5 * np.sin(a), 0.3], [0.0, 0.0, 0.08]))
        frames.append(cell.capture())
    below = frames[-1].T_world_camera
    frames[-1] = frames[-1].with_pose(Pose(below.rotation, below.translation - np.array([0.0, 0.0, 0.4])))
    write_view_folder(settings.data_dir / "recorded" / "boxes", frames, reference=mesh)
    return [f.T_world_camera for f in frames]


@pytest.mark.slow
def test_a_resumed_recorded_session_has_the_same_views_map_and_plan_and_goes_on(settings: AppSettings) -> None:
    from apphelpers import BASE_URL

    from app.main import create_app

    poses = recorded_boxes(settings)
    body = {"config": SMALL, "seed": 3, "source": {"kind": "recorded", "recorded": "boxes"}}

    def state(client: TestClient, sid: str) -> dict[str, Any]:
        st = client.get(f"/api/sessions/{sid}").json()
        export = client.get(f"/api/sessions/{sid}/export").json()
        return {
            "iteration": st["iteration"],
            "points": st["points"],
            "voxels": st["voxels"],
            "coverage": st["coverage"],
            "best": st["pending_plan"]["best"],
            "scores": [
                (c["index"], c["score"], c["eligible"]) for c in client.get(f"/api/sessions/{sid}/candidates").json()
            ],
            "views": [it["pose"]["position"] for it in export["iterations"]],
            "floor": export["config"]["voxel"]["floor"],
            "cloud": client.get(f"/api/sessions/{sid}/cloud.ply").content,
        }

    with TestClient(create_app(settings), base_url=BASE_URL) as a:
        sid = a.post("/api/sessions", json=body).json()["id"]
        a.post(f"/api/sessions/{sid}/capture")
        plan = a.post(f"/api/sessions/{sid}/plan").json()
        a.post(f"/api/sessions/{sid}/approve", json={"plan_id": plan["plan_id"], "index": plan["best"]["index"]})
        plan = a.post(f"/api/sessions/{sid}/plan").json()
        before = state(a, sid)
    assert before["iteration"] == 2 and len(before["scores"]) == len(poses)  # the recorded views only
    assert before["floor"] is False  # a view from under the plate top: no floor (devices.recorded.sees_from_below)
    recorded = np.array([p.translation for p in poses])
    assert all(np.min(np.linalg.norm(recorded - v, axis=1)) < 0.01 for v in before["views"])  # (ICP-refined)
    with TestClient(create_app(settings), base_url=BASE_URL) as b:
        r = b.post(f"/api/sessions/{sid}/resume")
        assert r.status_code == 200, r.text
        assert (r.json()["verified"], r.json()["mismatches"]) == (True, [])
        assert state(b, sid) == before  # the same views, voxels, cloud, coverage, plan, every score, config
        st = b.post(f"/api/sessions/{sid}/approve", json={"plan_id": plan["plan_id"], "index": plan["best"]["index"]})
        assert st.status_code == 200 and st.json()["iteration"] == 3
        got = b.get(f"/api/sessions/{sid}/export").json()["iterations"][2]["pose"]["position"]
        assert np.linalg.norm(recorded[plan["best"]["index"]] - got) < 0.01  # the planned recorded view
