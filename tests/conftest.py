"""The suite's one rule for parallel runs (``make test``: pytest-xdist, ``-n 3 --dist loadgroup
--no-loadscope-reorder``): the tests of a file run in one worker process, so a module's fixtures (a served app, a
bench run) are built once; a file marked ``xdist_group("name")`` shares its worker with the other files of that
group (the long, CPU-heavy ones, which must not starve each other's budgets). Every test gets its own node id
(xdist runs one test per id). The groups with a long test (``LONG_MARKS``) are handed out first, and the
controller writes the test modules' assert-rewritten bytecode while its workers start (:func:`rewrite_ahead`).

xdist's loadgroup tells its scheduler a test's group by appending ``@group`` to the node id in the worker; since
pytest 9.2 builds node ids from structured parts, the string xdist writes is ignored and every test was scheduled
on its own (pytest-xdist issue 1386, open): a file's tests ran on up to three workers, each building the file's
module fixtures, and the "heavy" group's two files ran side by side. The trylast hook
:func:`pytest_collection_modifyitems_group_suffix` writes the suffix where xdist's write did not take."""

from __future__ import annotations

import fnmatch
import gc
import sys
import threading
from pathlib import Path

import pytest

LONG_MARKS = ("slow", "e2e")
"""A group with a test marked so is handed out before the others (the Makefile turns xdist's own order, by the
number of tests, off): the long single-test files then no longer end the run on one worker while the others idle."""


@pytest.hookimpl(tryfirst=True)
def pytest_collection_modifyitems(config: pytest.Config, items: list[pytest.Item]) -> None:
    for item in items:
        if item.nodeid.rpartition("::")[2] != item.name and item.parent is not None:
            # schemathesis gives every operation's test one node id; xdist needs one each (pytest's own rule)
            item._id = item.parent.id.child(item.name)  # type: ignore[attr-defined]
        if item.get_closest_marker("xdist_group") is None:
            item.add_marker(pytest.mark.xdist_group(item.nodeid.split("::")[0]))
    if getattr(config.option, "loadgroup", False):
        items[:] = long_groups_first(items)


def _group(item: pytest.Item) -> str:
    mark = item.get_closest_marker("xdist_group")
    return "" if mark is None else str(mark.args[0] if mark.args else mark.kwargs.get("name", "default"))


def long_groups_first(items: list[pytest.Item]) -> list[pytest.Item]:
    """The items by group: the groups with a ``LONG_MARKS`` test first, then by their number of tests (most
    first), ties in collection order; a group's own tests keep their order."""
    groups: dict[str, list[pytest.Item]] = {}
    long: set[str] = set()
    for item in items:
        group = _group(item)
        groups.setdefault(group, []).append(item)
        if any(item.get_closest_marker(name) for name in LONG_MARKS):
            long.add(group)
    order = sorted(groups, key=lambda g: (g not in long, -len(groups[g])))  # stable: ties keep collection order
    return [item for group in order for item in groups[group]]


@pytest.hookimpl(trylast=True, specname="pytest_collection_modifyitems")
def pytest_collection_modifyitems_group_suffix(config: pytest.Config, items: list[pytest.Item]) -> None:
    """In an xdist worker of ``--dist loadgroup``: the ``@group`` suffix on every node id that lacks it (after
    xdist's own hook, which adds it with pytest < 9.2 only)."""
    if not getattr(config.option, "loadgroup", False):
        return
    for item in items:
        group = _group(item)
        if not group or item.nodeid.endswith(f"@{group}"):
            continue
        structured = getattr(item, "_id", None)
        if structured is not None and hasattr(structured, "parse"):
            item._id = type(structured).parse(f"{item.nodeid}@{group}")  # type: ignore[attr-defined]
        else:
            item._nodeid = f"{item.nodeid}@{group}"  # type: ignore[attr-defined]


@pytest.hookimpl(trylast=True)
def pytest_collection_finish(session: pytest.Session) -> None:
    """What collection built (the imported libraries, the test modules) moves to the collector's permanent
    generation: the full collections during the tests and pytest's at exit no longer walk it. Measured on the
    whole suite (three workers): their full collections 21.7 -> 16.6 CPU-s, the final ones 1.0-1.4 -> 0.5-1.0 s
    each."""
    gc.collect()
    gc.freeze()


def pytest_configure(config: pytest.Config) -> None:
    """In the xdist controller (which collects nothing): :func:`rewrite_ahead` in a thread while the workers start."""
    if getattr(config.option, "numprocesses", None) and not hasattr(config, "workerinput"):
        threading.Thread(target=rewrite_ahead, args=(config,), name="rewrite-ahead", daemon=True).start()


def rewrite_ahead(config: pytest.Config, root: Path = Path(__file__).parent) -> None:
    """Write pytest's assert-rewritten bytecode of every test module and conftest under ``root`` that has none, in
    the order the workers collect them, with pytest's own functions (``_pytest.assertion.rewrite``). On a fresh
    clone the three workers otherwise each rewrite all of them at once (4-5 s of CPU a worker); a worker that gets
    there first just rewrites the module itself, as before. Skipped where bytecode is not written or pytest's
    functions are not there."""
    try:
        from _pytest.assertion import rewrite
    except ImportError:
        return
    needed = ("assertstate_key", "get_cache_dir", "PYC_TAIL", "_read_pyc", "_rewrite_test", "_write_pyc")
    if sys.dont_write_bytecode or not all(hasattr(rewrite, name) for name in needed):
        return
    state = config.stash.get(rewrite.assertstate_key, None)
    if state is None:  # --assert=plain
        return
    patterns = ["conftest.py", *config.getini("python_files")]
    for source in sorted(root.rglob("*.py")):
        if "__pycache__" in source.parts or not any(fnmatch.fnmatch(source.name, p) for p in patterns):
            continue
        cache = rewrite.get_cache_dir(source)
        pyc = cache / (source.name[:-3] + rewrite.PYC_TAIL)
        try:
            if rewrite._read_pyc(source, pyc, state.trace) is not None:
                continue
            cache.mkdir(exist_ok=True)
            source_hash, code = rewrite._rewrite_test(source, config)
            rewrite._write_pyc(state, code, source_hash, pyc)
        except (OSError, SyntaxError):  # the worker that imports the module reports it
            continue
