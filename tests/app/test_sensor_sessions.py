"""Sessions on a simulated sensor and calibration error: the create request's ``camera``, the planner
config that follows it, accuracy per view, the refusal rule of the session loop and auto mode, resume.

All on the default simulated UR5 cell (real ray casting, real kinematics); refusals are forced with the fault
injector (``move_refused``: the arm refuses the move at move time; ``empty_frame``: a frame the planner cannot use).
"""

from __future__ import annotations

import json
from collections.abc import Iterator
from contextlib import contextmanager
from typing import Any

from apphelpers import BASE_URL, SMALL
from fastapi.testclient import TestClient

from app.main import create_app
from app.settings import AppSettings
from devices.calibration_error import CALIBRATIONS
from devices.sensors.presets import SENSORS
from workbench.journal.store import read_journal

D435 = {"sensor": "realsense-d435", "calibration": "typical"}


@contextmanager
def server(settings: AppSettings) -> Iterator[TestClient]:
    with TestClient(create_app(settings), base_url=BASE_URL) as c:
        yield c


def create(client: TestClient, **body: Any) -> str:
    r = client.post("/api/sessions", json={"config": SMALL, "seed": 3, **body})
    assert r.status_code == 201, r.text
    return r.json()["id"]


def planned(client: TestClient, **body: Any) -> tuple[str, dict[str, Any]]:
    sid = create(client, **body)
    assert client.post(f"/api/sessions/{sid}/capture").status_code == 200
    r = client.post(f"/api/sessions/{sid}/plan")
    assert r.status_code == 200, r.text
    return sid, r.json()


def eligible_by_score(client: TestClient, sid: str) -> list[int]:
    cands = client.get(f"/api/sessions/{sid}/candidates").json()
    return [c["index"] for c in sorted((c for c in cands if c["eligible"]), key=lambda c: -c["score"])]


def test_the_sensor_and_calibration_names_are_listed(client: TestClient) -> None:
    r = client.get("/api/sensors")
    assert r.status_code == 200
    assert r.json() == {"sensors": list(SENSORS), "calibrations": list(CALIBRATIONS)}
    assert r.json()["sensors"][0] == "ideal" and "realsense-d435" in r.json()["sensors"]


def test_a_bad_sensor_or_calibration_name_is_422_listing_the_names(client: TestClient) -> None:
    before = client.get("/api/sessions").json()
    r = client.post("/api/sessions", json={"config": SMALL, "camera": {"sensor": "kinect"}})
    assert r.status_code == 422
    detail = r.json()["detail"]
    assert "kinect" in detail and all(name in detail for name in SENSORS), detail
    r = client.post("/api/sessions", json={"config": SMALL, "camera": {"calibration": "perfect"}})
    assert r.status_code == 422 and all(name in r.json()["detail"] for name in CALIBRATIONS)
    r = client.post("/api/sessions", json={"config": SMALL, "camera": {"sensor": "ideal", "fov": 3}})
    assert r.status_code == 422
    assert client.get("/api/sessions").json() == before  # nothing created


def test_a_d435_session_steps_with_precision_and_f_per_view(settings: AppSettings) -> None:
    with server(settings) as c:
        sid = create(c, camera=D435)
        header = read_journal(settings.data_dir / "sessions" / sid).header
        camera = header["devices"]["camera"]
        assert (camera["sensor"], camera["calibration"]) == ("realsense-d435", "typical")
        noise = header["config"]["noise"]  # the planner config follows the camera (planner_config_for)
        assert noise["depth_z2"] > 0 and noise["fit_plate"] is True
        assert header["config"]["preprocess"]["support_min_points"] == 5
        assert c.post(f"/api/sessions/{sid}/capture").status_code == 200
        r = c.post(f"/api/sessions/{sid}/step", json={"count": 2})
        assert r.status_code == 200, r.text
        st = c.get(f"/api/sessions/{sid}").json()
        assert st["iteration"] == 3 and len(st["views"]) == 3
        for view in st["views"]:
            p, f, cov = view["precision_5mm"], view["fscore_5mm"], view["coverage"]
            assert 0.5 < p <= 1.0 and 0.0 < cov <= 1.0
            assert abs(f - 2 * p * cov / (p + cov)) < 0.02  # F of this view's precision and recall
            assert view["chamfer_mm"] > 0 and view["fscore_2mm"] <= f
        assert st["views"][-1]["coverage"] > st["views"][0]["coverage"]
        m = c.get(f"/api/sessions/{sid}/metrics").json()
        assert [p["precision_5mm"] for p in m["iterations"]] == [v["precision_5mm"] for v in st["views"]]
        assert [p["fscore_5mm"] for p in m["iterations"]] == [v["fscore_5mm"] for v in st["views"]]
        export = c.get(f"/api/sessions/{sid}/export").json()
        assert export["iterations"][0]["accuracy"]["precision_5mm"] == st["views"][0]["precision_5mm"]


def test_an_ideal_session_is_perfectly_precise(client: TestClient) -> None:
    sid = create(client)
    client.post(f"/api/sessions/{sid}/capture")
    view = client.get(f"/api/sessions/{sid}").json()["views"][0]
    assert view["precision_5mm"] > 0.99 and view["icp_rejected"] is None and view["refused"] == []


def test_a_refused_move_of_the_planners_choice_takes_the_next_candidate(client: TestClient) -> None:
    sid, plan = planned(client, faults={"schedule": [{"kind": "move_refused", "at": 2}]})
    ranked = eligible_by_score(client, sid)
    assert ranked[0] == plan["best"]["index"]
    r = client.post(f"/api/sessions/{sid}/approve", json={"plan_id": plan["plan_id"], "index": plan["best"]["index"]})
    assert r.status_code == 200, r.text
    st = client.get(f"/api/sessions/{sid}").json()
    assert (st["state"], st["iteration"], st["refused_moves"], st["error"]) == ("ready", 2, 1, None)
    assert st["views"][1]["refused"] == [{"candidate": ranked[0], "reason": "refused"}]
    export = client.get(f"/api/sessions/{sid}/export").json()
    refusal = export["refusals"][0]
    assert (refusal["candidate"], refusal["next"], refusal["plan_id"]) == (ranked[0], ranked[1], plan["plan_id"])
    assert "refused" in refusal["message"]
    taken = [d for d in export["decisions"] if d["plan_id"] == plan["plan_id"]]
    assert [d["index"] for d in taken] == [ranked[0], ranked[1]]


def test_an_unusable_frame_of_the_planners_choice_takes_the_next_candidate(client: TestClient) -> None:
    sid, plan = planned(client, faults={"schedule": [{"kind": "empty_frame", "at": 2}]})
    ranked = eligible_by_score(client, sid)
    r = client.post(f"/api/sessions/{sid}/approve", json={"plan_id": plan["plan_id"], "index": plan["best"]["index"]})
    assert r.status_code == 200, r.text
    st = client.get(f"/api/sessions/{sid}").json()
    assert (st["state"], st["iteration"], st["refused_moves"]) == ("ready", 2, 1)
    assert st["views"][1]["refused"] == [{"candidate": ranked[0], "reason": "frame_rejected"}]


def test_a_refused_override_is_422_and_the_state_stays(client: TestClient) -> None:
    sid, plan = planned(client, faults={"schedule": [{"kind": "move_refused", "at": 2}]})
    other = eligible_by_score(client, sid)[1]
    r = client.post(f"/api/sessions/{sid}/approve", json={"plan_id": plan["plan_id"], "index": other})
    assert r.status_code == 422, r.text
    st = client.get(f"/api/sessions/{sid}").json()
    assert st["iteration"] == 1 and st["refused_moves"] == 0
    assert st["pending_plan"]["plan_id"] == plan["plan_id"]  # the person's choice: the plan is theirs again


def test_auto_mode_goes_on_past_refused_moves(client: TestClient) -> None:
    faults = {"schedule": [{"kind": "move_refused", "at": 2}, {"kind": "move_refused", "at": 4}]}
    sid = create(client, faults=faults)
    assert client.post(f"/api/sessions/{sid}/capture").status_code == 200
    r = client.post(f"/api/sessions/{sid}/step", json={"count": 3})
    assert r.status_code == 200, r.text
    st = client.get(f"/api/sessions/{sid}").json()
    assert (st["iteration"], st["state"], st["error"]) == (4, "ready", None)
    assert st["refused_moves"] == 2
    assert [len(v["refused"]) for v in st["views"]] == [0, 1, 1, 0]


def test_a_sensor_session_with_a_refusal_resumes_with_no_mismatch(settings: AppSettings) -> None:
    with server(settings) as a:
        sid = create(a, camera=D435, faults={"schedule": [{"kind": "move_refused", "at": 2}]})
        a.post(f"/api/sessions/{sid}/capture")
        assert a.post(f"/api/sessions/{sid}/step", json={"count": 2}).status_code == 200
        plan = a.post(f"/api/sessions/{sid}/plan").json()
        before = a.get(f"/api/sessions/{sid}").json()
        cloud = a.get(f"/api/sessions/{sid}/cloud.ply").content
    with server(settings) as b:
        r = b.post(f"/api/sessions/{sid}/resume")
        assert r.status_code == 200, r.text
        assert (r.json()["verified"], r.json()["mismatches"]) == (True, [])
        after = b.get(f"/api/sessions/{sid}").json()
        for key in ("iteration", "points", "voxels", "coverage", "views", "refused_moves"):
            assert after[key] == before[key], key
        assert after["pending_plan"]["best"] == plan["best"]
        assert b.get(f"/api/sessions/{sid}/cloud.ply").content == cloud


def test_an_older_journal_without_camera_models_resumes_as_ideal(settings: AppSettings) -> None:
    with server(settings) as a:
        sid = create(a)
        a.post(f"/api/sessions/{sid}/capture")
        before = a.get(f"/api/sessions/{sid}").json()
    path = settings.data_dir / "sessions" / sid / "journal.jsonl"
    lines = path.read_text().splitlines()
    header = json.loads(lines[0])
    for key in ("sensor", "calibration"):
        del header["devices"]["camera"][key]  # as an older build wrote it
    del header["config"]["noise"]
    lines[0] = json.dumps(header)
    path.write_text("\n".join(lines) + "\n")
    with server(settings) as b:
        r = b.post(f"/api/sessions/{sid}/resume")
        assert r.status_code == 200, r.text
        assert r.json()["mismatches"] == []
        assert b.get(f"/api/sessions/{sid}").json()["voxels"] == before["voxels"]


def test_only_no_eligible_view_left_ends_the_step(client: TestClient) -> None:
    """Every eligible candidate of the plan refused at move time: the step fails (422 no eligible view left), the
    map unchanged and the plan pending again, every refusal journaled."""
    sid, plan = planned(client)
    eligible = eligible_by_score(client, sid)
    sid, plan = planned(
        client, faults={"schedule": [{"kind": "move_refused", "at": n} for n in range(2, len(eligible) + 2)]}
    )
    assert eligible_by_score(client, sid) == eligible  # the same seed and object: the same plan
    before = client.get(f"/api/sessions/{sid}").json()
    r = client.post(f"/api/sessions/{sid}/approve", json={"plan_id": plan["plan_id"], "index": plan["best"]["index"]})
    assert r.status_code == 422 and "no eligible view left" in r.json()["detail"], r.text
    assert f"{len(eligible)} candidate(s) refused" in r.json()["detail"]
    st = client.get(f"/api/sessions/{sid}").json()
    assert (st["state"], st["iteration"], st["voxels"]) == ("error", 1, before["voxels"])
    assert st["refused_moves"] == len(eligible) and st["pending_plan"]["plan_id"] == plan["plan_id"]
    refusals = client.get(f"/api/sessions/{sid}/export").json()["refusals"]
    assert [r["candidate"] for r in refusals] == eligible and refusals[-1]["next"] is None
