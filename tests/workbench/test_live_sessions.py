"""Live sessions are bounded (``max_live_sessions``): past the limit the least recently used idle session sleeps
to its journal, and a create is refused (AtCapacity, 503) only when every live one is busy. Idle sessions sleep
after ``idle_sleep`` seconds and wake intact on the next request (same map counts, same pending plan)."""

from __future__ import annotations

import contextlib
import time
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import pytest

from tests.helpers import SMALL, with_small_costs
from workbench.errors import AtCapacity
from workbench.registry.registry import SessionRegistry
from workbench.session.session import Session
from workbench.session.states import Action, State
from workbench.settings import WorkbenchSettings


@pytest.fixture
def registry(tmp_path: Path, request: pytest.FixtureRequest) -> Iterator[SessionRegistry]:
    options = getattr(request, "param", {})
    settings = with_small_costs(
        WorkbenchSettings(models_dir=tmp_path / "models", data_dir=tmp_path / "data", workers=False, **options)
    )
    registry = SessionRegistry(settings)
    yield registry
    registry.close()


def facts(session: Session) -> dict[str, Any]:
    status = session.status()
    pending = status["pending_plan"]
    return {
        "iteration": status["iteration"],
        "voxels": status["voxels"],
        "points": status["points"],
        "plan_id": pending and pending["plan_id"],
        "best": pending and pending["best"],
    }


def live_ids(registry: SessionRegistry) -> set[str]:
    return {s.id for s in registry.list()}


@pytest.mark.parametrize("registry", [{"max_live_sessions": 3}], indirect=True)
def test_40_creates_keep_at_most_the_limit_live_and_a_sleeper_wakes_intact(registry: SessionRegistry) -> None:
    first = registry.create("l-block", config=SMALL)
    first.capture()
    first.plan()
    before = facts(first)
    ids = [first.id]
    for _ in range(39):
        ids.append(registry.create("l-block", config=SMALL).id)
        assert len(registry.list()) <= 3
    listed = {s["id"]: s for s in registry.list_status()}
    assert set(listed) == set(ids)  # nothing lost: the rest sleep, listed from their journals
    assert live_ids(registry) == set(ids[-3:])
    assert listed[first.id]["state"] == "interrupted" and "asleep" in listed[first.id]["error"]
    woken = registry.get(first.id)  # any request wakes it
    assert facts(woken) == before and woken.state == State.PLANNED
    assert len(registry.list()) <= 3 and first.id in live_ids(registry)
    approved = woken.approve(before["plan_id"], index=before["best"]["index"])  # the woken plan is approvable
    assert approved["iteration"] == 2


@pytest.mark.parametrize("registry", [{"max_live_sessions": 2}], indirect=True)
def test_a_create_past_the_limit_with_every_session_busy_is_refused_clearly(registry: SessionRegistry) -> None:
    sessions = [registry.create("l-block", config=SMALL) for _ in range(2)]
    with contextlib.ExitStack() as held:
        for s in sessions:
            s.capture()
            held.enter_context(s.enter(Action.PLAN))  # planning (as a long plan would be): busy, so it cannot sleep
        with pytest.raises(AtCapacity, match=r"2 sessions are live, the limit \(server.max_live_sessions = 2\)"):
            registry.create("l-block", config=SMALL)
        assert live_ids(registry) == {s.id for s in sessions} and len(registry.list_status()) == 2


@pytest.mark.parametrize("registry", [{"idle_sleep": 0.4}], indirect=True)
def test_an_idle_session_sleeps_and_wakes_intact(registry: SessionRegistry) -> None:
    session = registry.create("mug", config=SMALL)
    session.capture()
    session.plan()
    before = facts(session)
    deadline = time.monotonic() + 10
    while session.id in live_ids(registry):
        assert time.monotonic() < deadline, "the idle session did not go to sleep"
        time.sleep(0.05)
    assert registry.status(session.id)["iteration"] == 1  # a tab opening it wakes it
    woken = registry.get(session.id)
    assert woken is not session and facts(woken) == before
