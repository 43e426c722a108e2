"""The ``reach`` layer (real viser server, raw websocket clients, the real UR5 model): the session's candidate
hemisphere coloured by what its cell reaches, drawn only while the layer is shown, with the legend's counts."""

from __future__ import annotations

from collections import Counter
from collections.abc import Iterator
from typing import Any

import numpy as np
import pytest
from fastapi.testclient import TestClient

from app.main import create_app
from app.scene.reachlayer import REACH_CLASSES, reach_class
from app.settings import AppSettings
from devices.config import CellConfig, DeviceConfig
from planner import BoundingBox
from planner.candidates import propose_candidates
from tests.viewer_wire import RawViewer, wait_for

SMALL_HEMISPHERE = {"voxel": {"resolution": 0.02}, "candidates": {"count": 24, "parallels": 3}}


@pytest.fixture
def scene_client(settings: AppSettings) -> Iterator[TestClient]:
    with TestClient(create_app(settings.replace(scene=True)), base_url="http://127.0.0.1") as c:
        yield c


def connect(client: TestClient, sid: str) -> tuple[str, RawViewer]:
    body = client.post("/api/viewer", json={"session": sid}).json()
    ticket = body["url"].split("ticket%3D")[1]
    raw = RawViewer(f"ws://127.0.0.1:{body['port']}/?ticket={ticket}", f"http://127.0.0.1:{body['port']}")
    vid = body["viewer"]
    assert wait_for(lambda: client.get(f"/api/scene/{vid}").json()["connected"], timeout=60.0)
    return vid, raw


def reach_points(client: TestClient, vid: str) -> Any:
    """The drawn /reach/points node's handle, or None."""
    drawing = client.app.state.scene.viewer(vid).drawing  # type: ignore[attr-defined]
    return drawing._handles.get("/reach/points")


def expected_colors(session: Any, candidates: Any) -> np.ndarray:
    """(N, 3) uint8: the class colour of each view as the session's cell answers it now."""
    answers = session.cell.reachability_many([c.T_world_camera for c in candidates])
    return np.array([REACH_CLASSES[reach_class(ok, why)][1] for ok, why in answers], dtype=np.uint8)


def test_the_reach_layer_colours_the_plans_candidates_by_the_cells_answers(
    scene_client: TestClient, planned_session
) -> None:
    sid, _ = planned_session(scene_client, config=SMALL_HEMISPHERE)
    vid, raw = connect(scene_client, sid)
    try:
        layers = scene_client.get(f"/api/scene/{vid}").json()["layers"]
        assert layers["reach"] is False
        assert "/reach/points" not in scene_client.get(f"/api/scene/{vid}").json()["nodes"]
        scene = scene_client.app.state.scene  # type: ignore[attr-defined]
        assert scene.reach.current(scene_client.app.state.registry.get(sid), None) is None  # type: ignore[attr-defined]

        assert scene_client.put(f"/api/scene/{vid}/layers", json={"reach": True}).status_code == 200
        assert wait_for(lambda: "/reach/points" in scene_client.get(f"/api/scene/{vid}").json()["nodes"], 60.0)
        session = scene_client.app.state.registry.get(sid)  # type: ignore[attr-defined]
        candidates = session.scene_data().plan.candidates
        assert len(candidates) == 24
        handle = reach_points(scene_client, vid)
        assert handle.points.shape == (24, 3)
        np.testing.assert_allclose(handle.points, np.stack([c.position for c in candidates]), atol=1e-6)
        colors = expected_colors(session, candidates)
        np.testing.assert_array_equal(handle.colors, colors)
        # the planner's eligibility agrees: a candidate it found unreachable is not coloured reachable
        green = np.array(REACH_CLASSES["reachable"][1], dtype=np.uint8)
        for i, reason in enumerate(plan_reasons(session)):
            if reason == "unreachable":
                assert not np.array_equal(colors[i], green), i
        # the legend counts the classes of the drawn views
        info = scene_client.get(f"/api/scene/{vid}").json()
        counts = Counter(tuple(int(v) for v in c) for c in colors)
        assert {r["class"]: r["count"] for r in info["reach"]} == {
            k: counts[rgb] for k, (_, rgb) in REACH_CLASSES.items() if counts[rgb]
        }
        assert [r["class"] for r in info["reach_classes"]] == list(REACH_CLASSES)
        # hidden: the node is hidden, not recomputed
        assert scene_client.put(f"/api/scene/{vid}/layers", json={"reach": False}).status_code == 200
        assert reach_points(scene_client, vid) is handle
        drawing = scene.viewer(vid).drawing
        assert drawing._handles["/reach"].visible is False
    finally:
        raw.close()


def plan_reasons(session: Any) -> list[str | None]:
    return list(session.scene_data().plan.ineligible_reasons)


def test_before_a_plan_the_default_hemisphere_and_a_reach_sphere_cell(settings: AppSettings, new_session) -> None:
    sphere = settings.replace(scene=True, devices=DeviceConfig(cell=CellConfig(kinematics="reach_sphere")))
    with TestClient(create_app(sphere), base_url="http://127.0.0.1") as client:
        sid = new_session(client, config=SMALL_HEMISPHERE)
        vid, raw = connect(client, sid)
        try:
            assert client.put(f"/api/scene/{vid}/layers", json={"reach": True}).status_code == 200
            assert wait_for(lambda: reach_points(client, vid) is not None, 60.0)
            session = client.app.state.registry.get(sid)  # type: ignore[attr-defined]
            assert session.scene_data().plan is None
            assert session.planner.voxel_map.bbox is None  # before the first view: about the object's own bounds
            lower, upper = np.asarray(session.scene_data().mesh.bounds, dtype=np.float64)
            config = session.config
            candidates, _, _ = propose_candidates(BoundingBox(lower, upper), config.candidates, config.partitions)
            handle = reach_points(client, vid)
            assert handle.points.shape == (24, 3)
            np.testing.assert_allclose(handle.points, np.stack([c.position for c in candidates]), atol=1e-6)
            colors = expected_colors(session, candidates)
            np.testing.assert_array_equal(handle.colors, colors)
            # the reach sphere: reachable inside the sphere, 'reach' outside, nothing else
            inside = [session.cell.is_reachable(c.T_world_camera) for c in candidates]
            want = [REACH_CLASSES["reachable" if ok else "reach"][1] for ok in inside]
            np.testing.assert_array_equal(handle.colors, np.array(want, dtype=np.uint8))
            assert any(inside)
        finally:
            raw.close()


def test_a_busy_session_gives_no_map(
    scene_client: TestClient, planned_session, monkeypatch: pytest.MonkeyPatch
) -> None:
    """The cell is not asked beside an action: a busy session gives no map, and an action that claims the session
    between two chunks of views ends the computation without a map of mixed answers."""
    from app.scene import reachlayer
    from workbench import BUSY, State

    sid, _ = planned_session(scene_client, config=SMALL_HEMISPHERE)
    session = scene_client.app.state.registry.get(sid)  # type: ignore[attr-defined]
    assert reachlayer.compute_reach_map(session) is not None
    moving = next(iter(BUSY))
    with session.lock:
        session._set_state(moving)
    try:
        assert reachlayer.compute_reach_map(session) is None
    finally:
        with session.lock:
            session._set_state(State.PLANNED)
    calls = {"n": 0}
    real = session.cell.reachability_many

    def claimed_after_first_chunk(poses: Any) -> Any:
        calls["n"] += 1
        if calls["n"] == 1:  # an action claims the session once this chunk has let go of the lock
            session._set_state(moving)
        return real(poses)

    session.cell.reachability_many = claimed_after_first_chunk
    monkeypatch.setattr(reachlayer, "CHUNK", 10)  # three chunks of the 24 views
    try:
        assert reachlayer.compute_reach_map(session) is None
    finally:
        del session.cell.reachability_many
        with session.lock:
            session._set_state(State.PLANNED)
    assert calls["n"] == 1
