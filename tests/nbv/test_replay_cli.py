"""``nbv replay DIR``: re-runs a journaled session headless, reproduces its metrics, and says when it cannot."""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from app.settings import AppSettings
from devices.ply import read_ply
from nbv.cli import main
from tests.helpers import SMALL

pytestmark = pytest.mark.slow  # tests/conftest.py: handed out with the long groups, first


@pytest.fixture(scope="module")
def journaled(tmp_path_factory: pytest.TempPathFactory) -> tuple[Path, dict, bytes]:
    """A session journaled by the workbench: first view, an override, two steps, a plan left pending."""
    from workbench.registry.registry import SessionRegistry

    data = tmp_path_factory.mktemp("replay") / "data"
    registry = SessionRegistry(AppSettings(scene=False, data_dir=data))
    wb = registry.create("mug", SMALL, seed=4)
    wb.capture()
    entry = wb.plan()
    other = next(i for i, s in enumerate(entry.plan.scores) if s.eligible and i != entry.plan.best_index)
    wb.approve(entry.plan_id, index=other)
    wb.auto.step(2)
    wb.plan()
    export = wb.export()
    from devices.ply import ply_bytes

    cloud = ply_bytes(wb.planner.cloud)
    registry.close()
    return data / "sessions" / wb.id, export, cloud


def test_replay_reproduces_the_journaled_metrics(journaled, tmp_path: Path, capsys) -> None:
    directory, export, cloud = journaled
    out = tmp_path / "out"
    assert main(["replay", str(directory), "--out", str(out)]) == 0
    text = capsys.readouterr().out
    assert "4 views, 4 plans: reproduced" in text and "DIFFERS" not in text
    doc = json.loads((out / "metrics.json").read_text())
    assert doc["reproduced"] is True and doc["mismatches"] == [] and doc["model"] == "mug"
    assert [it["points"] for it in doc["iterations"]] == [it["points"] for it in export["iterations"]]
    assert [it["coverage"] for it in doc["iterations"]] == [it["coverage"] for it in export["iterations"]]
    assert [it["next_view"] for it in doc["iterations"]] == [p["best_index"] for p in export["plans"]]
    assert [it["best_score"] for it in doc["iterations"]] == [p["best_score"] for p in export["plans"]]
    assert doc["final_coverage"] == export["iterations"][-1]["coverage"] > 0.5
    assert doc["config"]["voxel"]["resolution"] == 0.02 and set(doc["iterations"][0]) >= {"pose", "timings"}
    assert (out / "cloud.ply").read_bytes() == cloud
    assert len(read_ply(out / "cloud.ply")) == export["session"]["points"]


def tamper(directory: Path, target: Path, edit) -> Path:
    import shutil

    shutil.copytree(directory, target)
    path = target / "journal.jsonl"
    events = [json.loads(line) for line in path.read_text().splitlines()]
    edit(events)
    path.write_text("".join(json.dumps(e) + "\n" for e in events))
    return target


def test_replay_exits_1_when_the_plans_differ(journaled, tmp_path: Path, capsys) -> None:
    directory, _, _ = journaled

    def other_best(events: list[dict]) -> None:
        plan = next(e for e in events if e["kind"] == "plan")
        plan["best"]["index"] = (plan["best"]["index"] + 1) % 60

    def other_score(events: list[dict]) -> None:
        plan = [e for e in events if e["kind"] == "plan"][-1]
        plan["best"]["score"] *= 1.001

    for name, edit, expected in (("best", other_best, "best index"), ("score", other_score, "best score")):
        target = tamper(directory, tmp_path / name, edit)
        assert main(["replay", str(target), "--out", str(tmp_path / f"out-{name}")]) == 1
        text = capsys.readouterr().out
        assert "DIFFERS" in text and expected in text
        doc = json.loads((tmp_path / f"out-{name}" / "metrics.json").read_text())
        assert doc["reproduced"] is False and len(doc["mismatches"]) == 1 and expected in doc["mismatches"][0]


def test_replay_of_a_bad_directory_is_one_line_and_exit_2(tmp_path: Path, capsys) -> None:
    assert main(["replay", str(tmp_path / "nothing"), "--out", str(tmp_path / "o")]) == 2
    err = capsys.readouterr().err
    assert err.startswith("nbv: error:") and "no journal" in err and "Traceback" not in err
