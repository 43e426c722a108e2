"""``nbv bench --executor dask``: the same rows as the local pool, on a LocalCluster and on a scheduler
and two workers started as separate processes on loopback; a failed task keeps the others."""

from __future__ import annotations

import atexit
import csv
import os
import shutil
import socket
import subprocess
import sys
import tempfile
from collections.abc import Iterator
from pathlib import Path

import pytest

from nbv.cli import main
from planner.config import PlannerConfig
from workbench.evaluation.executors import run_dask
from workbench.evaluation.runs import MeshPayload, RunOutcome, RunTask

TINY = ["--views", "2", "--candidates", "40", "--resolution", "0.02", "--t-min", "2", "--t-max", "6"]
GRID = ["--models", "l-block", "box", "--planners", "projection,random", "--seeds", "1", *TINY]
TIMINGS = {
    "plan_seconds",
    "eval_seconds",
    "fit_seconds",
    "robot_seconds",
    "capture_seconds",
    "motion_planning_seconds",
    "plan_cpu_seconds",
    "cumulative_robot_seconds",
    "time_to_90",
    "time_to_95",
}
"""Columns with measured time in them (robot time includes the measured planning)."""

pytestmark = pytest.mark.slow


@pytest.fixture(scope="module", autouse=True)
def no_plots() -> Iterator[None]:
    """The benches of this module write every output but the plots (4 PNGs drawn by matplotlib: 2.8 s of CPU a
    bench, a quarter of the module's): the executor hands back the outcomes, the report is drawn from them in this
    process whatever ran them, and tests/nbv/test_bench.py checks the plots and report.html of the same grid."""
    with pytest.MonkeyPatch.context() as mp:
        mp.setattr("nbv.bench_report.plot", lambda *args, **kwargs: [])
        yield


Rows = list[tuple[tuple[str, str], ...]]


def rows(out: Path) -> Rows:
    """results.csv rows without the timing columns, sorted (runs finish in any order)."""
    with (out / "results.csv").open(newline="") as f:
        return sorted(tuple((k, v) for k, v in r.items() if k not in TIMINGS) for r in csv.DictReader(f))


CEILINGS = Path(tempfile.mkdtemp(prefix="nbv-dask-ceilings-"))
atexit.register(shutil.rmtree, CEILINGS, True)
"""One ceiling cache for the module: the executors are compared, the ceilings are computed once."""


def bench(out: Path, *extra: str, grid: list[str] = GRID) -> int:
    return main(["bench", *grid, "--out", str(out), "--ceiling-cache", str(CEILINGS), *extra])


@pytest.fixture(scope="module")
def local_rows(tmp_path_factory: pytest.TempPathFactory) -> list[tuple[tuple[str, str], ...]]:
    out = tmp_path_factory.mktemp("grid") / "a" / "local"
    assert bench(out, "--executor", "local", "--jobs", "2") == 0
    return rows(out)


def test_dask_local_cluster_gives_the_same_rows(tmp_path: Path, local_rows: list[tuple[tuple[str, str], ...]]) -> None:
    out = tmp_path / "a" / "dask"
    assert bench(out, "--executor", "dask", "--workers", "2") == 0
    got = rows(out)
    assert len(got) == 2 * 2 * 1 * 2  # models x planners x seeds x views
    assert got == local_rows
    assert {dict(r)["reachable_coverage"] for r in got} != {""}
    assert "Executor: dask (LocalCluster, 2 workers)" in (out / "summary.md").read_text()


def free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return int(s.getsockname()[1])


@pytest.fixture(scope="module")
def scheduler(tmp_path_factory: pytest.TempPathFactory) -> Iterator[str]:
    """``dask scheduler`` and two ``dask worker`` processes on 127.0.0.1; yields the address, then stops them."""
    from distributed import Client

    port = free_port()
    address = f"tcp://127.0.0.1:{port}"
    env = {**os.environ, "PYTHONPATH": os.pathsep.join([str(Path.cwd()), *sys.path])}
    common = ["--no-dashboard"]
    procs: list[subprocess.Popen[bytes]] = []
    log = (tmp_path_factory.mktemp("dask") / "dask.log").open("wb")
    try:
        procs.append(
            subprocess.Popen(
                [sys.executable, "-m", "dask", "scheduler", "--host", "127.0.0.1", "--port", str(port), *common],
                stdout=log,
                stderr=log,
                env=env,
            )
        )
        for _ in range(2):
            cmd = [
                sys.executable,
                "-m",
                "dask",
                "worker",
                address,
                "--host",
                "127.0.0.1",
                "--nthreads",
                "1",
                "--no-nanny",
            ]
            procs.append(subprocess.Popen([*cmd, *common], stdout=log, stderr=log, env=env))
        with Client(address, timeout=60) as client:
            client.wait_for_workers(2, timeout=90)
        yield address
    finally:
        for p in procs:  # single processes (no nanny): killing them leaves nothing behind
            p.kill()
        for p in procs:
            p.wait(timeout=30)
        log.close()


def test_dask_with_address_uses_the_external_cluster(
    tmp_path: Path, scheduler: str, local_rows: list[tuple[tuple[str, str], ...]]
) -> None:
    out = tmp_path / "a" / "external"
    grid = ["--models", "l-block", *GRID[3:]]  # one model: the other half of the grid adds no new path
    assert bench(out, "--executor", "dask", "--address", scheduler, grid=grid) == 0
    assert rows(out) == [r for r in local_rows if dict(r)["model"] == "l-block"]
    assert f"Executor: dask ({scheduler})" in (out / "summary.md").read_text()


def test_a_failed_dask_task_keeps_the_others(scheduler: str) -> None:
    from devices.builtins import resolve_model

    config = PlannerConfig().replace(termination={"max_views": 1}, voxel={"resolution": 0.02}, candidates={"count": 40})
    good = RunTask("box", "box", "random", 0, config, threads=1)
    bad = RunTask("box", "box", "no-such-planner", 0, config, threads=1)
    outcomes: list[RunOutcome] = []
    mesh = MeshPayload.of(resolve_model("box")[1])
    run_dask([good, bad], {"box": mesh}, outcomes.append, address=scheduler)
    by_planner = {o.planner: o for o in outcomes}
    assert len(outcomes) == 2
    assert by_planner["random"].error is None and len(by_planner["random"].rows) == 1
    assert by_planner["no-such-planner"].rows == [] and "no-such-planner" in (by_planner["no-such-planner"].error or "")


def test_cannot_reach_the_scheduler_is_one_line(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    address = f"tcp://127.0.0.1:{free_port()}"
    args = ["bench", "--models", "box", "--planners", "random", *TINY, "--no-reachable", "--out", str(tmp_path)]
    code = main([*args, "--executor", "dask", "--address", address])
    err = capsys.readouterr().err.strip()
    assert code == 2 and err.startswith(f"nbv: error: --address: OSError: no Dask scheduler at {address}")
    assert "\n" not in err
