"""tests/conftest.py's rules for parallel runs. On a small suite run the way ``make test`` runs ours: the tests of a
file share one xdist worker, the files of one ``xdist_group`` share one, and a group with a long test is handed out
first (pytest 9.2 silently broke xdist's own grouping: pytest-xdist issue 1386). And the controller writes the
test modules' assert-rewritten bytecode ahead of the workers."""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

import pytest

from tests.conftest import rewrite_ahead

ROOT = Path(__file__).resolve().parents[1]

RECORD = """
import os
from pathlib import Path


def record(name):
    with (Path(__file__).parent / "ran.txt").open("a") as f:
        f.write(f"{os.environ['PYTEST_XDIST_WORKER']} {name}\\n")
"""


def module(tests: int, mark: str = "") -> str:
    head = (
        f"import pytest\nfrom record import record\n\npytestmark = {mark}\n" if mark else "from record import record\n"
    )
    body = "".join(f"\n\ndef test_{i}():\n    record(__name__ + '.{i}')\n" for i in range(tests))
    return head + body


def test_a_file_shares_a_worker_a_group_shares_one_and_long_groups_go_first(tmp_path: Path) -> None:
    (tmp_path / "conftest.py").write_text((ROOT / "tests" / "conftest.py").read_text())
    (tmp_path / "record.py").write_text(RECORD)
    (tmp_path / "pytest.ini").write_text("[pytest]\nmarkers =\n  slow: long\n  e2e: browser\n")
    for name in "abcdef":
        (tmp_path / f"test_{name}.py").write_text(module(6))
    (tmp_path / "test_heavy1.py").write_text(module(3, 'pytest.mark.xdist_group("heavy")'))
    (tmp_path / "test_heavy2.py").write_text(module(3, 'pytest.mark.xdist_group("heavy")'))
    (tmp_path / "test_z_long.py").write_text(module(1, "pytest.mark.slow"))  # last by name and by count
    env = {k: v for k, v in os.environ.items() if not k.startswith("PYTEST_XDIST_")}  # not this run's worker
    env.update(PYTEST_DISABLE_PLUGIN_AUTOLOAD="1", PYTEST_PLUGINS="xdist.plugin")
    args = ["-n", "3", "--dist", "loadgroup", "--no-loadscope-reorder", "-q", "-p", "no:cacheprovider"]
    proc = subprocess.run(
        [sys.executable, "-m", "pytest", *args], cwd=tmp_path, env=env, capture_output=True, text=True, timeout=120
    )
    assert proc.returncode == 0, proc.stdout + proc.stderr
    ran = [line.split() for line in (tmp_path / "ran.txt").read_text().splitlines()]
    assert len(ran) == 6 * 6 + 3 + 3 + 1
    workers_of: dict[str, set[str]] = {}
    for worker, test in ran:
        workers_of.setdefault(test.split(".")[0], set()).add(worker)
    assert all(len(workers) == 1 for workers in workers_of.values()), workers_of
    assert workers_of["test_heavy1"] == workers_of["test_heavy2"]
    assert len(set().union(*workers_of.values())) == 3  # the groups are still spread over the workers
    (long_worker,) = workers_of["test_z_long"]
    assert next(test for worker, test in ran if worker == long_worker) == "test_z_long.0"


def test_the_controller_writes_the_rewritten_bytecode_pytest_then_loads(
    tmp_path: Path, pytestconfig: pytest.Config, monkeypatch: pytest.MonkeyPatch
) -> None:
    monkeypatch.setattr(sys, "dont_write_bytecode", False)  # as in make test
    (tmp_path / "test_sample.py").write_text("def test_it():\n    left = [1, 2]\n    assert left == [1, 3]\n")
    (tmp_path / "helper.py").write_text("X = 1\n")  # not a test module: pytest does not rewrite it
    rewrite_ahead(pytestconfig, tmp_path)
    cached = sorted(p.name for p in (tmp_path / "__pycache__").iterdir())
    assert len(cached) == 1 and cached[0].startswith("test_sample.") and "-pytest-" in cached[0]
    from _pytest.assertion.rewrite import _read_pyc

    code = _read_pyc(tmp_path / "test_sample.py", tmp_path / "__pycache__" / cached[0])
    assert code is not None
    namespace: dict[str, object] = {}
    exec(code, namespace)
    with pytest.raises(AssertionError) as failed:
        namespace["test_it"]()  # type: ignore[operator]
    assert "[1, 2] == [1, 3]" in str(failed.value)  # pytest's explanation: the rewritten assert, not a bare one
    before = (tmp_path / "__pycache__" / cached[0]).stat().st_mtime_ns
    rewrite_ahead(pytestconfig, tmp_path)  # up to date: left alone
    assert (tmp_path / "__pycache__" / cached[0]).stat().st_mtime_ns == before
