"""Exactly-once approval under races, and sessions that do not wait for each other."""

from __future__ import annotations

import threading
import time
from concurrent.futures import ThreadPoolExecutor

import httpx
from apphelpers import BASE_URL, SMALL
from fastapi.testclient import TestClient

from app.main import create_app
from workbench.errors import Conflict


def test_two_clients_approving_one_plan_move_once(client: TestClient, planned_session) -> None:
    sid, plan = planned_session(client)
    wb = client.app.state.registry.get(sid)  # type: ignore[attr-defined]
    arm_moves = wb.cell.arm.moves
    body = {"plan_id": plan["plan_id"], "index": plan["best"]["index"]}
    barrier = threading.Barrier(2)

    def approve() -> int:
        barrier.wait()
        return client.post(f"/api/sessions/{sid}/approve", json=body).status_code

    with ThreadPoolExecutor(2) as pool:
        codes = sorted(pool.map(lambda _: approve(), range(2)))
    assert codes == [200, 409]
    assert wb.cell.arm.moves == arm_moves + 1
    st = client.get(f"/api/sessions/{sid}").json()
    assert (st["iteration"], st["moves"]) == (2, 2)
    assert len(client.get(f"/api/sessions/{sid}/export").json()["decisions"]) == 1


def test_two_real_clients_racing_over_tcp_move_once(live_server, small_config) -> None:
    """Two HTTP clients on their own connections to a real server approve one plan_id at the same instant.

    A barrier inside the workbench proves both requests are in ``approve`` at the same time (a server that
    handled them one after the other would break it and fail the request); then exactly one moves."""
    clients = [httpx.Client(base_url=live_server.url, timeout=60) for _ in range(2)]
    try:
        api = clients[0]
        sid = api.post("/api/sessions", json={"config": small_config}).json()["id"]
        api.post(f"/api/sessions/{sid}/capture")
        wb = live_server.registry.get(sid)
        real_approve = wb.approve
        inside = threading.Barrier(2, timeout=20)

        def racing_approve(*args, **kwargs):
            inside.wait()  # both requests have reached the workbench: now they race for the lock
            return real_approve(*args, **kwargs)

        wb.approve = racing_approve
        for round_ in range(3):
            plan = api.post(f"/api/sessions/{sid}/plan").json()
            moves = wb.cell.arm.moves
            body = {"plan_id": plan["plan_id"], "index": plan["best"]["index"]}
            start = threading.Barrier(2)

            def approve(c: httpx.Client, body=body, start=start) -> httpx.Response:
                start.wait()
                return c.post(f"/api/sessions/{sid}/approve", json=body)

            with ThreadPoolExecutor(2) as pool:
                responses = list(pool.map(approve, clients))
            assert sorted(r.status_code for r in responses) == [200, 409], [r.text for r in responses]
            loser = next(r for r in responses if r.status_code == 409).json()["detail"]
            assert "busy" in loser or "already used" in loser
            assert wb.cell.arm.moves == moves + 1
            st = api.get(f"/api/sessions/{sid}").json()
            assert (st["iteration"], st["moves"]) == (round_ + 2, round_ + 2)
        decisions = api.get(f"/api/sessions/{sid}/export").json()["decisions"]
        assert len(decisions) == 3 and len({d["plan_id"] for d in decisions}) == 3
    finally:
        for c in clients:
            c.close()


def test_many_threads_approving_one_plan_move_once(client: TestClient, planned_session) -> None:
    sid, plan = planned_session(client)
    wb = client.app.state.registry.get(sid)  # type: ignore[attr-defined]
    arm_moves = wb.cell.arm.moves
    barrier = threading.Barrier(8)
    results: list[str] = []

    def approve() -> None:
        barrier.wait()
        try:
            wb.approve(plan["plan_id"], index=plan["best"]["index"])
            results.append("ok")
        except Conflict:
            results.append("409")

    threads = [threading.Thread(target=approve) for _ in range(8)]
    for t in threads:
        t.start()
    for t in threads:
        t.join()
    assert sorted(results) == ["409"] * 7 + ["ok"]
    assert wb.cell.arm.moves == arm_moves + 1


def test_a_busy_session_blocks_neither_reads_nor_other_sessions(
    client: TestClient, new_session, planned_session
) -> None:
    sid_a, plan_a = planned_session(client)
    sid_b = new_session(client)
    wb_a = client.app.state.registry.get(sid_a)  # type: ignore[attr-defined]
    release = threading.Event()
    entered = threading.Event()
    real_move = wb_a.cell.move_to

    def slow_move(
        pose, plate_angle=None, then=(), motion=None, capture_hz=0.0, on_frame=None
    ):  # session A's robot takes its time (Cell.move_to's args)
        entered.set()
        assert release.wait(30)
        return real_move(pose, plate_angle, then, motion, capture_hz=capture_hz, on_frame=on_frame)

    wb_a.cell.move_to = slow_move
    body = {"plan_id": plan_a["plan_id"], "index": plan_a["best"]["index"]}
    with ThreadPoolExecutor(1) as pool:
        pending = pool.submit(client.post, f"/api/sessions/{sid_a}/approve", json=body)
        assert entered.wait(30)
        t0 = time.perf_counter()
        assert client.get(f"/api/sessions/{sid_a}").json()["state"] == "moving"
        assert client.post(f"/api/sessions/{sid_a}/plan").status_code == 409  # busy: refused, not queued
        assert client.post(f"/api/sessions/{sid_b}/capture").status_code == 200
        assert client.post(f"/api/sessions/{sid_b}/plan").status_code == 200
        assert time.perf_counter() - t0 < 20
        assert not pending.done()
        release.set()
        assert pending.result(30).status_code == 200
    assert client.get(f"/api/sessions/{sid_a}").json()["iteration"] == 2
    assert client.get(f"/api/sessions/{sid_b}").json()["state"] == "planned"


def test_creates_released_together_never_pass_the_live_session_limit(settings) -> None:
    """8 creates at one instant with ``max_live_sessions = 2``: each is created (the older ones sleep to make room:
    a create reserves its place before its session exists), and never more than 2 are live at once."""
    with TestClient(create_app(settings.replace(max_live_sessions=2, idle_sleep=0.0)), base_url=BASE_URL) as client:
        registry = client.app.state.registry  # type: ignore[attr-defined]
        seen: list[int] = []
        registry.on_create.append(lambda _session: seen.append(len(registry.list())))
        barrier = threading.Barrier(8)

        def create() -> int:
            barrier.wait()
            return client.post("/api/sessions", json={"model": "l-block", "config": SMALL}).status_code

        with ThreadPoolExecutor(8) as pool:
            codes = list(pool.map(lambda _: create(), range(8)))
        assert codes == [201] * 8
        assert len(seen) == 8 and max(seen) <= 2, seen
        assert len(registry.list()) <= 2 and len(registry.list_status()) == 8  # the rest sleep, listed


def test_identical_uploads_at_the_same_moment_all_succeed(client: TestClient, settings, cube_obj) -> None:
    """8 uploads of the same name and bytes released together: each is stored (one content-addressed file, no
    temporary file left), each answers 201 with the same name."""
    barrier = threading.Barrier(8)

    def upload() -> tuple[int, str]:
        barrier.wait()
        r = client.post("/api/models", files={"file": ("same.obj", cube_obj.encode(), "text/plain")})
        return r.status_code, r.json().get("name", r.text)

    with ThreadPoolExecutor(8) as pool:
        answers = list(pool.map(lambda _: upload(), range(8)))
    assert [code for code, _ in answers] == [201] * 8, answers
    assert len({name for _, name in answers}) == 1
    stored = sorted(p.name for p in (settings.data_dir / "uploads").iterdir())
    assert stored == [answers[0][1].removeprefix("uploads/")]
