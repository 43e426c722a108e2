"""The arm in each tab's 3D view (real viser server, raw websocket clients, the real UR5 model and planner): drawn
at the cell's joints under /robot, the ghost and camera path of the selected target, an unreachable target's
reason, the preview animation on the ghost, and the executed move animated after an approval."""

from __future__ import annotations

import math
from collections.abc import Iterator
from typing import Any

import numpy as np
import pytest
from fastapi.testclient import TestClient

from app.main import create_app
from app.scene.robot import ghost_pose
from app.settings import AppSettings
from devices.arm.config import ArmConfig
from devices.config import CellConfig, DeviceConfig
from devices.protocols import UnreachableError
from tests.viewer_wire import RawViewer, wait_for

REASON_PREFIXES = ("no_ik", "joint_limit", "collision:", "no_path", "unreachable")


@pytest.fixture
def scene_client(settings: AppSettings) -> Iterator[TestClient]:
    with TestClient(create_app(settings.replace(scene=True)), base_url="http://127.0.0.1") as c:
        yield c


def connect(client: TestClient, sid: str) -> tuple[str, RawViewer]:
    body = client.post("/api/viewer", json={"session": sid}).json()
    ticket = body["url"].split("ticket%3D")[1]
    port = body["port"]
    raw = RawViewer(f"ws://127.0.0.1:{port}/?ticket={ticket}", f"http://127.0.0.1:{port}")
    vid = body["viewer"]
    assert wait_for(lambda: "/robot/arm" in client.get(f"/api/scene/{vid}").json()["nodes"], timeout=60.0)
    return vid, raw


def nodes(client: TestClient, vid: str) -> list[str]:
    return client.get(f"/api/scene/{vid}").json()["nodes"]


def robot_of(client: TestClient, vid: str) -> Any:
    return client.app.state.scene.viewer(vid).robot  # type: ignore[attr-defined]


def session_of(client: TestClient, sid: str) -> Any:
    return client.app.state.registry.get(sid)  # type: ignore[attr-defined]


def test_the_arm_is_drawn_with_the_ghost_of_the_planners_choice(scene_client: TestClient, planned_session) -> None:
    sid, plan = planned_session(scene_client)
    vid, raw = connect(scene_client, sid)
    try:
        wb = session_of(scene_client, sid)
        robot = robot_of(scene_client, vid)
        # the arm stands at the cell's joints and plate angle
        np.testing.assert_allclose(robot.q, wb.cell.arm.joint_positions())
        assert robot.angle == pytest.approx(wb.cell.angle)
        # the raw client received the arm's link meshes under /robot/arm and the ghost's under /robot/ghost
        links = ("base", "shoulder", "upperarm", "forearm", "wrist1", "wrist2", "wrist3")

        def missing() -> list[tuple[str, str]]:  # the link meshes not received yet (they stream in)
            meshes = {str(m["name"]) for m in raw.messages() if m.get("type") in ("GlbMessage", "MeshMessage")}
            return [
                (root, link)
                for root in ("/robot/arm/", "/robot/ghost/")
                for link in links
                if not any(n.startswith(root) and f"/{link}.dae" in n for n in meshes)
            ]

        assert wait_for(lambda: not missing(), timeout=30), missing()
        arm = scene_client.get(f"/api/sessions/{sid}/arm").json()
        assert arm["has_arm"] is True
        np.testing.assert_allclose(arm["joints"], wb.cell.arm.joint_positions())
        target = arm["target"]
        assert target["kind"] == "candidate" and target["index"] == plan["best"]["index"]
        assert target["reachable"], target["reason"]  # the planner's choice is reachable by construction
        # drawn by the scene's worker once the viewer connected (the move is not planned on viser's event thread)
        assert wait_for(lambda: {"/robot/ghost", "/robot/path"} <= set(nodes(scene_client, vid)), timeout=30)
        # the ghost's camera is where the candidate is (the plate turned to its angle)
        pose = ghost_pose(wb.cell.kinematics.model, np.array(target["joints"]), target["plate_angle"])
        cand = wb.pending.plan.candidates[plan["best"]["index"]]
        np.testing.assert_allclose(pose.translation, cand.position, atol=2e-3)
        assert target["duration"] > 0
        # every candidate the planner found unreachable has the cell's reason
        reasons = wb.pending.plan.ineligible_reasons
        expected = {str(i) for i, r in enumerate(reasons) if r == "unreachable"}
        assert set(arm["unreachable"]) == expected
        assert all(v.startswith(REASON_PREFIXES) for v in arm["unreachable"].values())
    finally:
        raw.ws.close()


def highest_first(plan: Any) -> list[int]:
    return sorted(range(len(plan.candidates)), key=lambda i: -plan.candidates[i].position[2])


def unreachable(cell: Any, index: int, plan: Any) -> bool:
    try:
        cell.plan_motion(plan.candidates[index].T_world_camera)
    except UnreachableError:
        return True
    return False


def test_an_unreachable_selection_has_no_ghost_and_its_reason(settings: AppSettings, planned_session) -> None:
    far = DeviceConfig(cell=CellConfig(arm=ArmConfig(base=(-1.0, 0.0, 0.0))))  # the hemisphere's top out of reach
    with TestClient(create_app(settings.replace(scene=True, devices=far)), base_url="http://127.0.0.1") as client:
        sid, _ = planned_session(client)
        vid, raw = connect(client, sid)
        try:
            wb = session_of(client, sid)
            index = next(i for i in highest_first(wb.pending.plan) if unreachable(wb.cell, i, wb.pending.plan))
            assert client.put(f"/api/sessions/{sid}/selection", json={"index": index}).status_code == 200
            target = client.get(f"/api/sessions/{sid}/arm").json()["target"]
            assert target["index"] == index and target["reachable"] is False
            assert target["reason"] and "unreachable" in target["reason"]
            assert "/robot/ghost" not in nodes(client, vid) and "/robot/path" not in nodes(client, vid)
            r = client.post(f"/api/sessions/{sid}/arm/preview")
            assert r.status_code == 422 and "unreachable" in r.json()["detail"]
            assert not robot_of(client, vid).animating
        finally:
            raw.ws.close()


def test_preview_animates_the_ghost_and_approve_animates_the_arm(scene_client: TestClient, planned_session) -> None:
    sid, plan = planned_session(scene_client)
    vid, raw = connect(scene_client, sid)
    try:
        wb = session_of(scene_client, sid)
        robot = robot_of(scene_client, vid)
        target = scene_client.get(f"/api/sessions/{sid}/arm").json()["target"]
        assert target["reachable"], target["reason"]
        q_before = wb.cell.arm.joint_positions().copy()
        r = scene_client.post(f"/api/sessions/{sid}/arm/preview", params={"speed": 4.0})
        assert r.status_code == 200, r.text
        assert r.json()["tabs"] == 1 and r.json()["seconds"] == pytest.approx(target["duration"] / 4.0)
        assert robot.animating
        np.testing.assert_allclose(wb.cell.arm.joint_positions(), q_before)  # a preview moves nothing
        assert wait_for(lambda: not robot.animating, timeout=60.0)
        assert scene_client.post(f"/api/sessions/{sid}/arm/preview", params={"speed": 0}).status_code == 422
        # approve: the sim arm executes the move; the view animates the executed trajectory to the new joints
        r = scene_client.post(
            f"/api/sessions/{sid}/approve", json={"plan_id": plan["plan_id"], "index": plan["best"]["index"]}
        )
        assert r.status_code == 200, r.text
        q_after = wb.cell.arm.joint_positions()
        assert not np.allclose(q_after, q_before)
        motion = wb.cell.last_motion
        assert motion is not None and motion.trajectory is not None
        np.testing.assert_allclose(motion.trajectory.positions[-1], q_after, atol=1e-9)
        assert wait_for(lambda: not robot.animating and np.allclose(robot.q, q_after), timeout=60.0)
        assert robot.angle == pytest.approx(wb.cell.angle)
        assert "/robot/ghost" not in nodes(scene_client, vid)  # no pending plan: no ghost
        assert scene_client.post(f"/api/sessions/{sid}/arm/preview").status_code == 409
    finally:
        raw.ws.close()


def test_a_reach_sphere_cell_draws_no_arm(settings: AppSettings, planned_session) -> None:
    sphere = settings.replace(scene=True, devices=DeviceConfig(cell=CellConfig(kinematics="reach_sphere")))
    with TestClient(create_app(sphere), base_url="http://127.0.0.1") as client:
        sid, _ = planned_session(client)
        body = client.post("/api/viewer", json={"session": sid}).json()
        raw = RawViewer(f"ws://127.0.0.1:{body['port']}/?ticket={body['url'].split('ticket%3D')[1]}",
                        f"http://127.0.0.1:{body['port']}")  # fmt: skip
        try:
            vid = body["viewer"]
            assert wait_for(lambda: client.get(f"/api/scene/{vid}").json()["connected"])
            assert not any(n.startswith("/robot") for n in nodes(client, vid))
            arm = client.get(f"/api/sessions/{sid}/arm").json()
            assert arm["has_arm"] is False and arm["target"] is None
            assert client.post(f"/api/sessions/{sid}/arm/preview").status_code == 409
            assert math.isfinite(arm["plate_angle"])
        finally:
            raw.ws.close()


def test_a_custom_pose_gets_the_ghost_or_its_reason(scene_client: TestClient, planned_session) -> None:
    sid, plan = planned_session(scene_client)
    vid, raw = connect(scene_client, sid)
    try:
        wb = session_of(scene_client, sid)
        # the planner's choice as a custom pose: reachable, the ghost's camera on it
        pose = plan["best"]["pose"]
        assert scene_client.put(f"/api/sessions/{sid}/custom_pose", json={"pose": pose}).json()["reachable"]
        target = scene_client.get(f"/api/sessions/{sid}/arm").json()["target"]
        assert target["kind"] == "custom" and target["index"] is None and target["reachable"]
        ghost = ghost_pose(wb.cell.kinematics.model, np.array(target["joints"]), target["plate_angle"])
        np.testing.assert_allclose(ghost.translation, pose["position"], atol=2e-3)
        assert wait_for(lambda: "/robot/ghost" in nodes(scene_client, vid))
        # two metres out: no ghost, no path, the reason
        far = {"position": [2.0, 0.0, 0.3], "wxyz": pose["wxyz"]}
        assert scene_client.put(f"/api/sessions/{sid}/custom_pose", json={"pose": far}).json()["reachable"] is False
        target = scene_client.get(f"/api/sessions/{sid}/arm").json()["target"]
        assert target["kind"] == "custom" and target["reachable"] is False and target["reason"]
        assert not {"/robot/ghost", "/robot/path"} & set(nodes(scene_client, vid))
    finally:
        raw.ws.close()


def test_deleting_the_session_takes_the_whole_arm_out_of_its_tabs_without_warnings(
    scene_client: TestClient, planned_session
) -> None:
    """A deleted session's tabs lose every /robot node (the arm, the ghost, their links and meshes) with one removal
    per top frame: viser removes a node's descendants, so removing each URDF mesh after its frame warned once per
    mesh (62 warnings in a suite run)."""
    import warnings

    sid, _ = planned_session(scene_client)
    vid, raw = connect(scene_client, sid)
    try:
        viewer = scene_client.app.state.scene.viewer(vid)  # type: ignore[attr-defined]
        scene = viewer.client.scene
        drawn = [name for name in scene._handle_from_node_name if name.startswith("/robot/")]
        assert len(drawn) > 20 and any(name.startswith("/robot/ghost/") for name in drawn)
        with warnings.catch_warnings(record=True) as caught:
            warnings.simplefilter("always")
            assert scene_client.delete(f"/api/sessions/{sid}").status_code == 204
        assert [str(w.message) for w in caught if "removed node" in str(w.message)] == []
        assert [name for name in scene._handle_from_node_name if name.startswith("/robot/")] == []
        assert not any(n.startswith("/robot/") for n in nodes(scene_client, vid))
    finally:
        raw.close()
