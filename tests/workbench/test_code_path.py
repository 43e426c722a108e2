"""Worker processes import the working directory's code first (a Python 3.11 forkserver): the commands that start
them refuse a directory holding another copy of the project, with a message saying where to run from."""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

import workbench
from nbv.cli import main
from workbench import shadowing_code

REPO = Path(workbench.__file__).resolve().parent.parent

CHILD = """
import multiprocessing
import planner

if __name__ == "__main__":
    context = multiprocessing.get_context("forkserver")
    context.set_forkserver_preload(["planner"])  # as the bench and the session workers preload theirs
    with context.Pool(1) as pool:
        child = pool.apply(eval, ("__import__('planner').__file__",))
    print(planner.__file__)
    print(child)
"""


def decoy(root: Path) -> Path:
    """A directory holding a package named like one of ours (another checkout, say)."""
    (root / "planner").mkdir(parents=True)
    (root / "planner" / "__init__.py").write_text("DECOY = True\n")
    return root


def test_a_forkserver_worker_imports_the_working_directorys_copy_and_the_check_says_so(tmp_path: Path) -> None:
    here = decoy(tmp_path / "other-checkout")
    script = tmp_path / "start_a_worker.py"
    script.write_text(CHILD)
    env = {**os.environ, "PYTHONPATH": str(REPO)}
    done = subprocess.run(
        [sys.executable, str(script)], cwd=here, env=env, capture_output=True, text=True, timeout=120, check=True
    )
    parent, child = (Path(line).resolve() for line in done.stdout.split())
    assert parent == REPO / "planner" / "__init__.py"  # the parent runs the code PYTHONPATH names
    assert child == here / "planner" / "__init__.py"  # its worker the directory's: the trap
    reason = shadowing_code(here)
    assert reason is not None
    assert str(here / "planner") in reason and str(REPO / "planner") in reason and f"run it from {REPO} " in reason


def test_no_reason_in_the_checkout_itself_or_in_a_directory_without_our_packages(tmp_path: Path) -> None:
    assert shadowing_code(REPO) is None
    (tmp_path / "planner").mkdir()  # a folder of that name without a package in it is no copy of the code
    assert shadowing_code(tmp_path) is None


def test_bench_refuses_to_start_its_workers_there(tmp_path: Path, monkeypatch, capsys) -> None:
    here = decoy(tmp_path)
    monkeypatch.chdir(here)
    code = main(["bench", "--models", "mug", "--planners", "projection", "--views", "2", "--out", str(tmp_path / "o")])
    assert code == 2
    err = capsys.readouterr().err
    assert err.startswith("nbv: error: the working directory holds a package 'planner'")
    assert not (tmp_path / "o").exists()  # refused before anything ran or was written
