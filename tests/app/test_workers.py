"""Heavy work runs in worker processes: the server answers during the heaviest plan the API accepts, DELETE and
Stop kill a running job at once (the worker's PID is gone), a job over its budget is killed and leaves the
session in state error with the map unchanged, idle workers are evicted and come back, SIGTERM stops the
server within 5 s."""

from __future__ import annotations

import copy
import os
import signal
import threading
import time
from pathlib import Path
from typing import Any

import httpx
import numpy as np
import pytest
from apphelpers import SMALL, free_port, running_server
from test_admission import FROZEN, HealthProbe

from app.settings import AppSettings
from tests.helpers import wait_until
from tests.servers import serve_process
from workbench.planning import plan_in

HEAVIEST: dict[str, Any] = {
    "voxel": {"resolution": 0.0064, "max_extent": 1.0},
    "cluster": {"search": "exhaustive", "t_min": 1, "t_max": 60, "max_iter": 1000, "tol": 1e-8},
    "candidates": {"count": 833, "parallels": 30},
}
"""About the heaviest config the API accepts (156 voxels per axis: 3.8 M voxels, just under the server's default
``max_session_voxels``; 60 exhaustive fits, 100 k projections)."""
PLAN_HEAVY: dict[str, Any] = {**HEAVIEST, "voxel": {"resolution": 0.01}}
"""As heavy a plan, a capture 30 times cheaper (100 voxels per axis)."""


def pid_gone(pid: int, within: float) -> bool:
    """The process ``pid`` has ended (or is a zombie) within ``within`` seconds."""
    deadline = time.monotonic() + within
    while time.monotonic() < deadline:
        try:
            with open(f"/proc/{pid}/stat") as fh:
                if fh.read().split(") ")[1].startswith("Z"):
                    return True
        except FileNotFoundError:
            return True
        time.sleep(0.02)
    return False


def busy_worker(live: Any, sid: str, within: float = 30.0) -> int:
    """The PID of ``sid``'s worker once a job runs there."""
    worker = live.registry.get(sid).worker
    deadline = time.monotonic() + within
    while time.monotonic() < deadline:
        if worker.busy and worker.pid is not None:
            return worker.pid
        time.sleep(0.01)
    raise AssertionError("no job started in the worker")


def in_thread(fn: Any) -> tuple[threading.Thread, dict[str, Any]]:
    box: dict[str, Any] = {}

    def run() -> None:
        box["response"] = fn()

    thread = threading.Thread(target=run, daemon=True)
    thread.start()
    return thread, box


def test_delete_kills_the_heaviest_plan_at_once_while_health_answers(settings: AppSettings) -> None:
    with (
        running_server(settings.replace(port=free_port())) as live,
        httpx.Client(base_url=live.url, timeout=120) as api,
    ):
        sid = api.post("/api/sessions", json={"config": HEAVIEST}).json()["id"]
        assert api.post(f"/api/sessions/{sid}/capture").status_code == 200
        with HealthProbe(live.url) as probe:
            thread, box = in_thread(lambda: api.post(f"/api/sessions/{sid}/plan"))
            pid = busy_worker(live, sid)
            wait_until(
                lambda: (live.registry.get(sid).progress_json() or {}).get("step", 0) >= 2, 30.0, "plan under way"
            )
            t0 = time.monotonic()
            assert httpx.delete(f"{live.url}/api/sessions/{sid}", timeout=5).status_code == 204
            assert time.monotonic() - t0 < 1.0
            assert pid_gone(pid, 1.0), "the worker still runs after DELETE"
            thread.join(10)
        assert not thread.is_alive(), box
        cut = box["response"]  # the session is gone: nothing to retry
        assert cut.status_code == 410 and "was deleted" in cut.json()["detail"], cut.text
        assert not probe.failures and probe.worst < FROZEN, (probe.worst, probe.failures)
        assert httpx.get(f"{live.url}/api/sessions/{sid}").status_code == 404


def test_a_plan_over_its_budget_is_killed_and_the_session_goes_on(settings: AppSettings) -> None:
    with running_server(settings.replace(port=free_port(), plan_budget=0.02)) as live:
        api = httpx.Client(base_url=live.url, timeout=120)
        sid = api.post("/api/sessions", json={"config": SMALL}).json()["id"]
        assert api.post(f"/api/sessions/{sid}/capture").status_code == 200
        before = api.get(f"/api/sessions/{sid}").json()
        pid = live.registry.get(sid).worker.pid
        t0 = time.monotonic()
        r = api.post(f"/api/sessions/{sid}/plan")
        assert r.status_code == 503 and "over its budget of 0.02 s" in r.json()["detail"], r.text
        assert time.monotonic() - t0 < 5.0 and pid_gone(pid, 1.0)
        st = api.get(f"/api/sessions/{sid}").json()
        assert st["state"] == "error" and "budget" in st["error"]
        assert (st["voxels"], st["points"], st["iteration"]) == (before["voxels"], before["points"], 1)
        assert st["pending_plan"] is None and st["retry"] is None  # no plan came out of the killed job
        # plan again (a budget that suffices): a fresh worker takes it from the session's state
        live.registry.get(sid).plan_budget = 60.0
        r = api.post(f"/api/sessions/{sid}/plan")
        assert r.status_code == 200 and api.get(f"/api/sessions/{sid}").json()["state"] == "planned", r.text


def test_stop_kills_a_running_plan_of_auto_mode(settings: AppSettings) -> None:
    with (
        running_server(settings.replace(port=free_port())) as live,
        httpx.Client(base_url=live.url, timeout=120) as api,
    ):
        sid = api.post("/api/sessions", json={"config": PLAN_HEAVY}).json()["id"]
        assert api.post(f"/api/sessions/{sid}/capture").status_code == 200
        assert api.post(f"/api/sessions/{sid}/auto", json={"count": 3}).status_code == 202
        pid = busy_worker(live, sid)
        t0 = time.monotonic()
        assert api.post(f"/api/sessions/{sid}/stop").status_code == 200
        assert pid_gone(pid, 1.0) and time.monotonic() - t0 < 1.5
        assert live.registry.get(sid).auto.join(10)
        st = api.get(f"/api/sessions/{sid}").json()
        assert (st["state"], st["iteration"], st["error"]) == ("ready", 1, None)


def test_idle_workers_are_evicted_and_come_back(settings: AppSettings) -> None:
    with running_server(settings.replace(port=free_port(), max_idle_workers=1)) as live:
        api = httpx.Client(base_url=live.url, timeout=120)
        sids = [api.post("/api/sessions", json={"config": SMALL}).json()["id"] for _ in range(2)]
        for sid in sids:
            assert api.post(f"/api/sessions/{sid}/capture").status_code == 200
        workers = [live.registry.get(sid).worker for sid in sids]
        assert workers[0].pid is None and workers[1].pid is not None  # the older idle one was stopped
        server_pid = os.getpid()
        assert workers[1].pid != server_pid
        r = api.post(f"/api/sessions/{sids[0]}/plan")  # its worker starts again from the session's state
        assert r.status_code == 200 and workers[0].pid is not None and workers[1].pid is None


@pytest.mark.slow
def test_sigterm_stops_the_server_within_5_s_during_a_plan(tmp_path: Path, models_dir: Path) -> None:
    log = tmp_path / "serve.log"
    with serve_process(tmp_path / "data", models_dir, log, timeout=120) as (proc, api):
        sid = api.post("/api/sessions", json={"config": PLAN_HEAVY}).json()["id"]
        assert api.post(f"/api/sessions/{sid}/capture").status_code == 200
        url = str(api.base_url).rstrip("/")
        in_thread(lambda: httpx.post(f"{url}/api/sessions/{sid}/plan", timeout=120))
        wait_until(lambda: api.get(f"/api/sessions/{sid}").json()["progress"] is not None, 30.0, "the plan runs")
        (tracker,) = children_running(proc.pid, "multiprocessing.resource_tracker")
        t0 = time.monotonic()
        proc.send_signal(signal.SIGTERM)
        proc.wait(10)
        assert time.monotonic() - t0 < 5.0, log.read_text()[-2000:]
    journal = (tmp_path / "data" / "sessions" / sid / "journal.jsonl").read_text().splitlines()
    assert any('"capture"' in line for line in journal)  # what happened before the signal is on disk
    # the worker's event was released with its session: the resource tracker, which outlives the server and reports
    # what it is left to clean up, finds nothing (uvicorn ends the process by re-raising SIGTERM: no exit handlers)
    wait_until(lambda: not running(tracker), 30.0, "the resource tracker exits")
    assert "leaked" not in log.read_text(), log.read_text()[-2000:]


def running(pid: int) -> bool:
    """The process exists and is no zombie."""
    try:
        stat = Path(f"/proc/{pid}/stat").read_text()
    except OSError:
        return False
    return stat[stat.rindex(")") + 2] != "Z"


def children_running(parent: int, module: str) -> list[int]:
    """The pids of ``parent``'s child processes whose command line names ``module``."""
    found = []
    for entry in Path("/proc").iterdir():
        try:
            stat = (entry / "stat").read_text()
            ppid = int(stat[stat.rindex(")") + 2 :].split()[1])
            if ppid == parent and module in (entry / "cmdline").read_bytes().decode(errors="replace"):
                found.append(int(entry.name))
        except (OSError, ValueError):
            continue
    return found


def test_an_arm_session_plans_in_its_worker_with_the_servers_verdicts(settings: AppSettings) -> None:
    """The default cell (the UR5): each plan runs in the worker (its job count grows) and equals the plan the
    server's own cell makes of the same map (eligibility, reasons, scores, the best view), and the approved
    best view moves the arm: no ``no_ik`` for a candidate the worker found reachable."""
    with (
        running_server(settings.replace(port=free_port())) as live,
        httpx.Client(base_url=live.url, timeout=120) as api,
    ):
        sid = api.post("/api/sessions", json={"config": SMALL}).json()["id"]
        session = live.registry.get(sid)
        assert session.cell.kinematics is not None
        assert api.post(f"/api/sessions/{sid}/capture").status_code == 200
        unreachable = 0
        for _ in range(3):
            jobs, before = session.worker.jobs, copy.deepcopy(session.planner)
            plan = api.post(f"/api/sessions/{sid}/plan").json()
            assert session.worker.jobs == jobs + 1, "the plan did not run in the worker"
            theirs = session.pending.plan
            mine = plan_in(session.cell, before)
            assert theirs.best_index == mine.best_index == plan["best"]["index"] is not None
            assert [s.eligible for s in theirs.scores] == [s.eligible for s in mine.scores]
            assert theirs.ineligible_reasons == mine.ineligible_reasons
            np.testing.assert_allclose([s.score for s in theirs.scores], [s.score for s in mine.scores])
            unreachable += theirs.ineligible_reasons.count("unreachable")
            r = api.post(
                f"/api/sessions/{sid}/approve", json={"plan_id": plan["plan_id"], "index": plan["best"]["index"]}
            )
            assert r.status_code == 200, r.text
        assert unreachable > 0  # the arm's reach left candidates out: the worker used the arm, not a sphere
