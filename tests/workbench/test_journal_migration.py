"""A journal written by the code before the workbench/ restructure (format 1, commit 0ee1866) still resumes.

The fixture (tests/workbench/fixtures/journal_v1/) was written by that build through its REST API: the first
view, an approval, an override, a config change and a pending plan, on a 160 x 120 camera so it stays small.
``expected.json`` is what that build reported for it.
"""

from __future__ import annotations

import json
import shutil
from pathlib import Path

import pytest

from workbench.registry.registry import SessionRegistry
from workbench.settings import WorkbenchSettings

FIXTURE = Path(__file__).parent / "fixtures" / "journal_v1"
EXPECTED = json.loads((FIXTURE / "expected.json").read_text())


@pytest.fixture
def old_data(tmp_path: Path) -> WorkbenchSettings:
    sid = EXPECTED["id"]
    shutil.copytree(FIXTURE / sid, tmp_path / "data" / "sessions" / sid)
    return WorkbenchSettings(data_dir=tmp_path / "data", models_dir=tmp_path)


def test_an_old_journal_is_listed_as_interrupted_with_its_facts(old_data: WorkbenchSettings) -> None:
    registry = SessionRegistry(old_data)
    status = registry.status(EXPECTED["id"])
    before = EXPECTED["status"]
    assert status["state"] == "interrupted" and status["iteration"] == before["iteration"] == 3
    assert (status["coverage"], status["points"], status["voxels"]) == (
        before["coverage"],
        before["points"],
        before["voxels"],
    )


def test_an_old_journal_resumes_to_the_same_map_and_the_same_pending_plan(old_data: WorkbenchSettings) -> None:
    registry = SessionRegistry(old_data)
    session, rebuilt = registry.resume(EXPECTED["id"])
    try:
        assert rebuilt.mismatches == [] and rebuilt.interrupted is None
        pending = session.pending
        assert pending is not None and pending.plan_id == EXPECTED["pending_plan"]["plan_id"]
        best = EXPECTED["pending_plan"]["best"]
        assert pending.plan.best_index == best["index"]
        assert float(pending.plan.scores[best["index"]].score) == pytest.approx(best["score"], rel=1e-9)
        export = session.export()
        rows = [{k: r[k] for k in ("iteration", "coverage", "points", "decision")} for r in export["iterations"]]
        assert rows == EXPECTED["iterations"]
        assert [d["kind"] for d in export["decisions"]] == ["approve", "override"]
        assert all(r["growth"] is not None for r in export["iterations"][1:])  # filled in from the replay
        assert all(p["fits"] for p in export["plans"])  # the old plan events had no BIC curves: replayed
        assert export["config"]["partitions"]["revisit_deg"] == 20  # the journaled config change
        # and the session goes on: approve the resumed plan
        session.approve(pending.plan_id, index=best["index"])
        assert session.status()["iteration"] == 4
    finally:
        registry.close()
