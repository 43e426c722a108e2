"""The ``path`` layer: the camera frustums along the move to the selected view, before approval (real viser server,
a raw websocket client, the real UR5 model and planner). The path starts where the camera stands and ends at the
selected view, its frames at the session's capture rate (else the preview's), follows the plate's turn round the
object, is re-drawn for another selection, is gone once the view is approved, and the approval still plans its move
once."""

from __future__ import annotations

import math
import threading
from collections.abc import Iterator
from typing import Any

import numpy as np
import pytest
from fastapi.testclient import TestClient

from app.main import create_app
from app.scene.movetarget import ArmTarget
from app.scene.pathlayer import MAX_FRUSTUMS, PREVIEW_HZ, frustum_edges, path_preview
from app.settings import AppSettings
from devices.builtins import make_builtin
from devices.config import CameraConfig, CellConfig
from devices.move_capture import MovePath, capture_times
from devices.sim import make_sim_cell
from planner import Pose
from tests.helpers import SMALL, orbit_view
from tests.viewer_wire import RawViewer, click_message, owner_of, wait_for
from tests.workbench.test_approve_motion import count_plans

SMALL_CAMERA = CameraConfig(width=80, height=60, fx=76.0, fy=76.0, cx=39.5, cy=29.5)


@pytest.fixture
def scene_client(settings: AppSettings) -> Iterator[TestClient]:
    with TestClient(create_app(settings.replace(scene=True)), base_url="http://127.0.0.1") as c:
        yield c


def _pose(d: dict[str, Any]) -> Pose:
    return Pose.from_wxyz(np.asarray(d["wxyz"]), np.asarray(d["position"]))


def _near(a: Pose, b: Pose, metres: float, radians: float) -> bool:
    """Whether ``a`` and ``b`` are within ``metres`` of each other and their orientations within ``radians``."""
    cos = (np.trace(a.rotation.T @ b.rotation) - 1.0) / 2.0
    angle = math.acos(min(1.0, max(-1.0, cos)))
    return bool(np.linalg.norm(a.translation - b.translation) <= metres and angle <= radians)


def test_the_frames_are_at_the_capture_rate_or_the_preview_rate_and_thinned_for_drawing() -> None:
    cell = make_sim_cell(make_builtin("l-block", 0.2), SMALL_CAMERA, CellConfig(), seed=0)
    view = orbit_view(np.array([0.0, 0.0, 0.08]), 40, 100, 0.45)
    motion = cell.plan_motion(view)
    start = cell.pose
    target = ArmTarget(("p", "candidate", 0), "candidate", 0, motion, None, MovePath.of(cell, motion))
    off = path_preview(target, 0.0)
    assert off is not None and off.rate_hz == PREVIEW_HZ and not off.captured
    np.testing.assert_allclose(off.times, capture_times(motion.duration, PREVIEW_HZ))
    assert len(off.times) == math.ceil(motion.duration * PREVIEW_HZ) - 1 >= 3
    assert _near(off.line[0], start, 1e-9, 1e-6) and _near(off.line[-1], view, 1e-6, 1e-5)
    on = path_preview(target, 60.0)
    assert on is not None and on.captured and len(on.poses) == math.ceil(motion.duration * 60.0) - 1
    times, poses = on.drawn()
    assert len(poses) == MAX_FRUSTUMS < len(on.poses) and times[0] == on.times[0] and times[-1] == on.times[-1]
    # the outlines: 8 edges per frame, every apex at its frame's centre
    edges = frustum_edges(poses, 0.8, 4 / 3, 0.03)
    assert edges.shape == (8 * MAX_FRUSTUMS, 2, 3)
    np.testing.assert_allclose(edges[::8, 0], [p.translation for p in poses], atol=1e-6)
    assert path_preview(ArmTarget(("p", "candidate", 1), "candidate", 1, None, "no_ik"), 0.0) is None


RATE = 3.0
"""Frames per second the session of the page's test captures during moves."""


@pytest.mark.slow
def test_the_page_previews_the_path_of_the_selected_view_until_it_is_approved(
    scene_client: TestClient, monkeypatch: pytest.MonkeyPatch
) -> None:
    client = scene_client
    r = client.post("/api/sessions", json={"model": "l-block", "config": SMALL, "move_capture": RATE})
    assert r.status_code == 201, r.text
    sid = r.json()["id"]
    assert client.post(f"/api/sessions/{sid}/capture").status_code == 200
    plan = client.post(f"/api/sessions/{sid}/plan").json()
    body = client.post("/api/viewer", json={"session": sid}).json()
    port, vid = body["port"], body["viewer"]
    raw = RawViewer(f"ws://127.0.0.1:{port}/?ticket={body['url'].split('ticket%3D')[1]}", f"http://127.0.0.1:{port}")
    scene = client.app.state.scene  # type: ignore[attr-defined]
    session = client.app.state.registry.get(sid)  # type: ignore[attr-defined]
    cell = session.cell
    try:

        def drawn() -> Any:
            v = scene.viewer(vid)
            return None if v.drawing is None else v.drawing.path

        assert wait_for(lambda: drawn() is not None, timeout=60.0)
        assert {"/path/frustums", "/path/edges", "/path/line"} <= set(client.get(f"/api/scene/{vid}").json()["nodes"])
        assert client.get(f"/api/scene/{vid}").json()["layers"]["path"] is True
        best = plan["best"]["index"]
        r = client.get(f"/api/sessions/{sid}/plan/path")
        assert r.status_code == 200, r.text
        path = r.json()
        assert path["target"]["index"] == best and path["target"]["reachable"]
        # from where the camera stands to the planner's choice, in the move's time, at the session's capture rate
        assert _near(_pose(path["start"]), cell.pose, 1e-6, 1e-5)
        end = _pose(path["end"])
        view = session.pending.plan.candidates[best].T_world_camera
        assert _near(end, view, 2e-3, 5e-3)
        assert path["duration"] == pytest.approx(path["target"]["duration"]) and path["duration"] > 0.5
        assert path["rate_hz"] == RATE and path["captured"] is True
        times = [f["t"] for f in path["frames"]]
        np.testing.assert_allclose(times, capture_times(path["duration"], RATE))
        assert times[0] > 0 and times[-1] < path["duration"]
        # what the viewer drew is what the REST read says
        preview = drawn()
        assert len(preview.poses) == len(times)
        np.testing.assert_allclose([p.translation for p in preview.poses], [f["position"] for f in path["frames"]])
        # the way goes round the object: while the plate turns (the arm still) the camera keeps its height and
        # its distance from the plate's axis, and its azimuth changes by the turn
        move = preview.target.path
        assert move is not None and move.retract_seconds == 0.0 and abs(move.turn) > 0.2
        turning = [p for t, p in zip(preview.times, preview.poses, strict=True) if t <= move.turn_seconds]
        start = cell.pose.translation
        assert len(turning) >= 2
        for p in turning:
            assert abs(p.translation[2] - start[2]) < 1e-6
            assert abs(np.linalg.norm(p.translation[:2]) - np.linalg.norm(start[:2])) < 1e-6
        assert max(np.linalg.norm(p.translation - start) for p in turning) > 0.05

        # a click on another candidate in the 3D view: the path re-drawn to it, the move planned on the scene's
        # worker thread (never viser's event thread); asking again plans nothing more
        other = next(c.index for c in session.pending.plan.scores if c.eligible and c.index != best)
        threads: list[str] = []
        plan_motion = cell.plan_motion

        def recorded(*args: Any, **kwargs: Any) -> Any:
            threads.append(threading.current_thread().name)
            return plan_motion(*args, **kwargs)

        monkeypatch.setattr(cell, "plan_motion", recorded)
        raw.send(click_message("/candidates", other, owner_of(raw.messages(), "/candidates")))
        assert wait_for(lambda: drawn() is not None and drawn().target.index == other, timeout=30.0)
        assert threads == ["scene-work"]
        again = client.get(f"/api/sessions/{sid}/plan/path").json()
        assert again["target"]["index"] == other
        other_view = session.pending.plan.candidates[other].T_world_camera
        assert _near(_pose(again["end"]), other_view, 2e-3, 5e-3)
        assert _near(drawn().line[-1], other_view, 2e-3, 5e-3)
        # a custom pose (the gizmo's override): the path goes there
        third = next(c.index for c in session.pending.plan.scores if c.eligible and c.index not in (best, other))
        custom = session.pending.plan.candidates[third].T_world_camera
        r = client.put(f"/api/sessions/{sid}/custom_pose", json={"pose": custom.to_dict()})
        assert r.status_code == 200 and r.json()["reachable"], r.text
        assert wait_for(lambda: drawn() is not None and drawn().target.kind == "custom", timeout=30.0)
        assert _near(drawn().line[-1], custom, 2e-3, 5e-3) and _near(drawn().line[0], cell.pose, 1e-6, 1e-5)
        planned = count_plans(monkeypatch, cell.kinematics)
        client.get(f"/api/sessions/{sid}/plan/path")
        assert planned == []  # the previewed move is kept for its selection
        # approve: the move planned once (as without the preview), the path gone, nothing left to read
        r = client.post(f"/api/sessions/{sid}/approve", json={"plan_id": plan["plan_id"], "pose": custom.to_dict()})
        assert r.status_code == 200, r.text
        assert len(planned) == 1
        assert wait_for(lambda: drawn() is None, timeout=30.0)
        nodes = set(client.get(f"/api/scene/{vid}").json()["nodes"])
        assert not {"/path/frustums", "/path/edges", "/path/line"} & nodes
        assert client.get(f"/api/sessions/{sid}/plan/path").status_code == 409
    finally:
        raw.ws.close()
