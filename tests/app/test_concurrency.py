"""Exactly-once approval under races, and sessions that do not wait for each other."""

from __future__ import annotations

import threading
import time
from concurrent.futures import ThreadPoolExecutor

from fastapi.testclient import TestClient

from app.errors import ConflictError


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
        except ConflictError:
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

    def slow_move(pose):  # the robot of session A takes its time
        entered.set()
        assert release.wait(30)
        return real_move(pose)

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
