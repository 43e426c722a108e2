"""nbv/import_path.py: folders holding packages named like ours move behind the folder ``nbv`` came from, and child
interpreters (a forkserver started with ``-c``) are kept from putting them first."""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

import pytest

import nbv
from nbv.import_path import holds_ours, plan_fix

REPO = Path(nbv.__file__).resolve().parents[1]
STDLIB = str(Path(os.__file__).parent)


def package(folder: Path, name: str, body: str = "") -> Path:
    (folder / name).mkdir(parents=True, exist_ok=True)
    (folder / name / "__init__.py").write_text(body)
    return folder


def test_nothing_changes_in_the_checkout_or_without_our_names(tmp_path: Path) -> None:
    path = ["", STDLIB, str(REPO)]
    fix = plan_fix(path, {"PYTHONPATH": str(REPO)}, REPO, REPO)  # run from the checkout itself
    assert fix.sys_path == path and fix.environ == {} and fix.shadowing == []
    (tmp_path / "app").mkdir()  # a folder without __init__.py is a namespace portion: ours still wins over it
    (tmp_path / "tools").mkdir()
    (tmp_path / "tools" / "__init__.py").write_text("")
    fix = plan_fix(["", STDLIB, str(REPO)], {}, tmp_path, REPO)
    assert fix.sys_path == ["", STDLIB, str(REPO)] and fix.environ == {} and fix.shadowing == []


def test_the_working_folder_moves_behind_the_installed_packages(tmp_path: Path) -> None:
    lab = package(tmp_path / "lab", "app")
    site = package(package(tmp_path / "site-packages", "app"), "nbv")
    fix = plan_fix(["", STDLIB, str(site), "/elsewhere"], {}, lab, site)
    assert fix.sys_path == [STDLIB, str(site), "", "/elsewhere"]  # the lab's other modules stay importable
    assert fix.environ == {"PYTHONSAFEPATH": "1"}  # a -c child would put the working folder first
    assert fix.shadowing == ["", str(lab.resolve())]
    # python -m nbv: the working folder is first as a full path; the console script: not on the path at all
    assert plan_fix([str(lab), STDLIB, str(site)], {}, lab, site).sys_path == [STDLIB, str(site), str(lab)]
    script = plan_fix(["/venv/bin", STDLIB, str(site)], {}, lab, site)
    assert script.sys_path == ["/venv/bin", STDLIB, str(site)] and script.environ == {"PYTHONSAFEPATH": "1"}


def test_pythonpath_entries_with_our_names_leave_the_childrens_pythonpath(tmp_path: Path) -> None:
    lab = package(tmp_path / "lab", "planner", "raise ImportError")
    other = package(tmp_path / "other", "tools")
    site = package(tmp_path / "site-packages", "nbv")
    late = package(tmp_path / "late", "app")  # after ours on PYTHONPATH: harmless, kept
    env = {"PYTHONPATH": os.pathsep.join([str(other), str(lab), str(site), str(late)])}
    fix = plan_fix([str(other), str(lab), str(site), str(late), STDLIB], env, tmp_path, site)
    assert fix.sys_path == [str(other), str(site), str(lab), str(late), STDLIB]
    assert fix.environ == {"PYTHONPATH": os.pathsep.join([str(other), str(site), str(late)])}
    assert fix.shadowing == [str(lab)]
    only = plan_fix([str(lab), STDLIB, str(site)], {"PYTHONPATH": str(lab)}, tmp_path, site)
    assert only.environ == {"PYTHONPATH": None}  # nothing left: the variable goes


def test_an_editable_install_gets_its_folder_ahead_of_the_shadow(tmp_path: Path) -> None:
    lab = package(tmp_path / "lab", "workbench")
    checkout = package(tmp_path / "checkout", "workbench")  # found by the editable install's finder, not the path
    fix = plan_fix([str(lab), STDLIB, "/site-packages"], {}, lab, checkout)
    assert fix.sys_path == [str(checkout.resolve()), str(lab), STDLIB, "/site-packages"]


def test_holds_ours_sees_packages_and_modules_only(tmp_path: Path) -> None:
    assert not holds_ours(tmp_path)
    (tmp_path / "devices.py").write_text("")
    assert holds_ours(tmp_path)
    assert not holds_ours(tmp_path, ("planner",))


CHILD = """
import multiprocessing, os, sys
import nbv  # first, as the console script and python -m nbv do
import app, planner

if __name__ == "__main__":
    method = sys.argv[1]
    context = multiprocessing.get_context(method)
    if method == "forkserver":
        context.set_forkserver_preload(["planner"])  # as the bench and the session workers preload ours
    with context.Pool(1) as pool:  # spawn: as Dask's LocalCluster starts its workers
        child = pool.apply(eval, ("__import__('planner').__file__",))
    print(app.__file__, planner.__file__, child, os.environ.get("PYTHONSAFEPATH"), os.environ.get("PYTHONPATH"))
"""


@pytest.mark.parametrize("method", ["forkserver", "spawn"])
def test_a_worker_started_from_a_lab_folder_imports_ours(tmp_path: Path, method: str) -> None:
    """The trap: a forkserver imports its preloads with its own path, the working folder and PYTHONPATH first; a
    spawned child (a Dask worker of ``nbv bench --executor dask``) must follow the parent's fixed path."""
    lab = package(package(tmp_path / "lab", "app", "NAME = 'the lab app'\n"), "planner", "NAME = 'the lab planner'\n")
    script = tmp_path / "start_a_worker.py"
    script.write_text(CHILD)
    env = {**os.environ, "PYTHONPATH": os.pathsep.join([str(lab), str(REPO)])}
    env.pop("PYTHONSAFEPATH", None)
    done = subprocess.run(
        [sys.executable, str(script), method], cwd=lab, env=env, capture_output=True, text=True, timeout=120, check=True
    )
    app_file, parent, child, safe, python_path = done.stdout.split()
    assert Path(app_file) == REPO / "app" / "__init__.py"
    assert Path(parent) == Path(child) == REPO / "planner" / "__init__.py"
    assert (safe, python_path) == ("1", str(REPO))
