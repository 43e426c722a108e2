"""Sleep and wake without side effects: a viewer follows its session across them, a request in flight keeps its
session live (no sleep, no Stop of another tab cuts its read off), a read cut off answers what happened (never 422),
and a status read of a sleeping session never fails."""

from __future__ import annotations

import threading
from collections.abc import Iterator
from concurrent.futures import ThreadPoolExecutor
from typing import Any

import pytest
from apphelpers import BASE_URL, SMALL, registry_of
from fastapi.testclient import TestClient

from app.main import create_app
from app.settings import AppSettings
from tests.viewer_wire import RawViewer, session_nodes, wait_for
from workbench.errors import AtCapacity
from workbench.session.states import Action
from workbench.workers.client import JobKilled, SessionWorker


def _create(client: TestClient) -> str:
    r = client.post("/api/sessions", json={"model": "l-block", "config": SMALL})
    assert r.status_code == 201, r.text
    return r.json()["id"]


def _live(client: TestClient) -> set[str]:
    return {s.id for s in registry_of(client).list()}


def _viewer(client: TestClient, sid: str) -> tuple[str, RawViewer]:
    body = client.post("/api/viewer", json={"session": sid}).json()
    ticket = body["url"].split("ticket%3D")[1]
    raw = RawViewer(f"ws://127.0.0.1:{body['port']}/?ticket={ticket}", f"http://127.0.0.1:{body['port']}")
    assert wait_for(lambda: "/views/1/frustum" in client.get(f"/api/scene/{body['viewer']}").json()["nodes"])
    return body["viewer"], raw


@pytest.fixture
def one_live(settings: AppSettings) -> Iterator[TestClient]:
    """A server with the 3D scene that keeps one session live (``max_live_sessions = 1``)."""
    with TestClient(create_app(settings.replace(scene=True, max_live_sessions=1)), base_url=BASE_URL) as c:
        yield c


def test_a_viewer_follows_its_session_across_sleep_and_wake(one_live: TestClient) -> None:
    """A tab that shows A before A sleeps, and a tab opened after A woke, both receive every later change of A
    (a woken session is a new object: its viewers listen to it again)."""
    a = _create(one_live)
    assert one_live.post(f"/api/sessions/{a}/capture").status_code == 200
    _, before = _viewer(one_live, a)
    try:
        _create(one_live)  # B: A sleeps
        assert a not in _live(one_live)
        assert one_live.get(f"/api/sessions/{a}").json()["iteration"] == 1  # A wakes (B sleeps)
        assert _live(one_live) == {a}
        _, after = _viewer(one_live, a)
        try:
            marks = before.mark(), after.mark()
            r = one_live.post(f"/api/sessions/{a}/step", json={"count": 1})
            assert r.status_code == 200, r.text
            for raw, mark in zip((before, after), marks, strict=True):
                got = lambda raw=raw, mark=mark: session_nodes([m for _, _, ms in raw.frames[mark:] for m in ms])  # noqa: E731
                assert wait_for(lambda got=got: "/views/2/frustum" in got()), (
                    f"no scene message after the step: {got()}"
                )
        finally:
            after.close()
    finally:
        before.close()


@pytest.fixture
def sleepy(settings: AppSettings) -> Iterator[TestClient]:
    """A server that keeps one session live, without the scene."""
    with TestClient(create_app(settings.replace(max_live_sessions=1)), base_url=BASE_URL) as c:
        yield c


def _two_views(client: TestClient) -> str:
    sid = _create(client)
    assert client.post(f"/api/sessions/{sid}/capture").status_code == 200
    assert client.post(f"/api/sessions/{sid}/step", json={"count": 2}).status_code == 200
    return sid


@pytest.fixture
def timeline_running(monkeypatch: pytest.MonkeyPatch) -> threading.Event:
    """Set while a worker runs a timeline job (its process has it); the job then waits until the event clears:
    what happens meanwhile happens mid-job."""
    running = threading.Event()
    real = SessionWorker._run

    def run(self: SessionWorker, kind: str, *args: Any) -> Any:
        if kind != "timeline":
            return real(self, kind, *args)
        conn, _ = self._started()
        running.set()
        wait_for(lambda: not running.is_set(), timeout=30)  # the test acts, then lets the job go on
        if conn is not self._conn:  # killed meanwhile: the job ends as a killed job does
            raise JobKilled(f"timeline: {self._reason or 'the worker process died'}")
        return real(self, kind, *args)

    monkeypatch.setattr(SessionWorker, "_run", run)
    return running


def _mid_timeline(client: TestClient, sid: str, running: threading.Event, act: Any) -> tuple[int, str]:
    """GET the timeline of ``sid``; while its rebuild runs, ``act()``; the timeline's (status, detail)."""
    with ThreadPoolExecutor(1) as pool:
        future = pool.submit(client.get, f"/api/sessions/{sid}/timeline")
        assert running.wait(30), "the timeline job did not start"
        try:
            act()
        finally:
            running.clear()
        r = future.result(60)
    return r.status_code, r.text


def test_the_idle_sweeper_does_not_put_a_session_to_sleep_mid_read(sleepy: TestClient, timeline_running) -> None:
    sid = _two_views(sleepy)
    registry = registry_of(sleepy)
    slept: list[bool] = []
    code, text = _mid_timeline(sleepy, sid, timeline_running, lambda: slept.append(registry.sleep(sid)))
    assert slept == [False] and code == 200, text
    assert registry.sleep(sid)  # once the read has ended, it sleeps


def test_a_create_past_the_limit_does_not_put_a_session_to_sleep_mid_read(sleepy: TestClient, timeline_running) -> None:
    """The create waits for the read (the held session is idle), then puts the session to sleep: both succeed."""
    sid = _two_views(sleepy)
    pool = ThreadPoolExecutor(1)
    created: list[Any] = []

    def create() -> None:
        created.append(pool.submit(sleepy.post, "/api/sessions", json={"model": "l-block", "config": SMALL}))
        wait_for(lambda: sid not in _live(sleepy), timeout=2.0)  # time for the create to make room (or wait)

    try:
        code, text = _mid_timeline(sleepy, sid, timeline_running, create)
        assert code == 200, text
        assert created[0].result(60).status_code == 201
    finally:
        pool.shutdown()
    assert len(_live(sleepy)) == 1 and sid not in _live(sleepy)


def test_a_stop_from_another_tab_does_not_kill_a_timeline_read(sleepy: TestClient, timeline_running) -> None:
    """Auto mode runs (its state), another tab reads the timeline; a Stop ends auto mode, not the read."""
    sid = _two_views(sleepy)
    session = registry_of(sleepy).get(sid)
    with session.enter(Action.AUTO):  # in auto mode, between two of its jobs
        code, text = _mid_timeline(sleepy, sid, timeline_running, lambda: sleepy.post(f"/api/sessions/{sid}/stop"))
    assert code == 200, text


def test_a_read_cut_off_answers_what_happened_never_422(sleepy: TestClient, timeline_running) -> None:
    """The session closed under a timeline read (shutdown): 503 with what happened, a valid request."""
    sid = _two_views(sleepy)
    session = registry_of(sleepy).get(sid)
    assert session.worker is not None
    code, text = _mid_timeline(sleepy, sid, timeline_running, session.worker.close)
    assert code == 503 and "cut off" in text, text


def test_a_status_read_of_a_sleeping_session_never_fails(sleepy: TestClient) -> None:
    """Every live session busy (it cannot wake now): the status comes from the journal."""
    a = _two_views(sleepy)
    b = _create(sleepy)  # a sleeps
    assert sleepy.post(f"/api/sessions/{b}/capture").status_code == 200
    session_b = registry_of(sleepy).get(b)
    with session_b.enter(Action.PLAN):  # b is busy: a cannot wake (no room)
        with pytest.raises(AtCapacity):
            registry_of(sleepy).get(a)
        r = sleepy.get(f"/api/sessions/{a}")
        assert r.status_code == 200, r.text
        assert r.json()["iteration"] == 3 and "asleep" in r.json()["error"]
