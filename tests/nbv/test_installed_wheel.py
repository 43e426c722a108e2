"""The tool as a user installs it: the wheel built from the checkout, installed into an environment of its own, run
from a lab's project folder that holds its own ``app/`` and ``planner/`` packages (also on ``PYTHONPATH``).

The folder's packages write a marker when imported and are useless to us (``app`` has no ``settings``, ``planner``
raises ImportError): scan, serve (a session's capture and plan in its worker process, a fork of the forkserver) and
bench (the local process pool) must work and never import them. The wheel is installed without network:
a venv without pip, the wheel installed by the shared venv's pip, and a ``.pth`` line that appends the shared
venv's site-packages for the dependencies (a folder added by a ``.pth`` line has its own ``.pth`` files ignored, so
the shared venv's editable install of this checkout does not leak in; the other ``.pth`` files' imports, cmeel's
for pinocchio, are copied).
"""

from __future__ import annotations

import csv
import json
import os
import shutil
import signal
import subprocess
import sys
import sysconfig
import time
import zipfile
from dataclasses import dataclass
from pathlib import Path

import httpx
import pytest

from tests.helpers import SMALL, free_port, small_costs_toml

REPO = Path(__file__).resolve().parents[2]
PACKAGES = ("planner", "devices", "workbench", "app", "nbv")

pytestmark = pytest.mark.slow

DECOY = """import pathlib
with open(pathlib.Path(__file__).resolve().parents[1] / "imported.txt", "a") as f:
    f.write(__name__ + "\\n")
"""


@dataclass
class Installed:
    """The fresh environment's interpreter and console script, and the lab's folder."""

    python: Path
    nbv: Path
    lab: Path

    def env(self, on_pythonpath: bool) -> dict[str, str]:
        """The environment of a command: none of the test run's Python variables; the lab's folder on PYTHONPATH
        when ``on_pythonpath``."""
        env = {k: v for k, v in os.environ.items() if not k.startswith("PYTHON") and k != "PYTEST_PLUGINS"}
        env |= {"OMP_NUM_THREADS": "1", "OPENBLAS_NUM_THREADS": "1", "PYTHONDONTWRITEBYTECODE": "1"}
        if on_pythonpath:
            env["PYTHONPATH"] = str(self.lab)
        return env

    @property
    def marker(self) -> Path:
        """Written by the lab's packages when something imports them."""
        return self.lab / "imported.txt"

    def run(self, *args: str, on_pythonpath: bool, timeout: float = 120) -> subprocess.CompletedProcess[str]:
        done = subprocess.run(
            list(args), cwd=self.lab, env=self.env(on_pythonpath), capture_output=True, text=True, timeout=timeout
        )
        assert done.returncode == 0, done.stdout[-2000:] + done.stderr[-3000:]
        assert "Traceback" not in done.stderr, done.stderr[-3000:]
        return done


def build_wheel(out: Path) -> Path:
    """The wheel of a copy of the checkout's sources (a build in the checkout would leave build/ there, whose stale
    files a later build would package)."""
    src = out / "src"
    ignore = shutil.ignore_patterns("__pycache__", "*.pyc")
    for name in PACKAGES:
        shutil.copytree(REPO / name, src / name, ignore=ignore)
    for name in ("pyproject.toml", "README.md"):
        shutil.copy2(REPO / name, src / name)
    pip = [sys.executable, "-m", "pip", "wheel", "--no-deps", "--no-build-isolation", "--no-index", "-q"]
    subprocess.run([*pip, "-w", str(out / "dist"), str(src)], check=True, capture_output=True, timeout=120)
    (wheel,) = (out / "dist").glob("nbv_workbench-*.whl")
    return wheel


def shared_site_pth() -> str:
    """The ``.pth`` text that appends the shared venv's site-packages and runs its ``.pth`` files' imports (cmeel's
    puts pinocchio on the path), all but the editable install's."""
    site = Path(sysconfig.get_paths()["purelib"])
    lines = [str(site)]
    for pth in sorted(site.glob("*.pth")):
        if pth.name.startswith("__editable__"):
            continue
        lines += [line for line in pth.read_text().splitlines() if line.startswith(("import ", "import\t"))]
    return "\n".join(lines) + "\n"


@pytest.fixture(scope="module")
def installed(tmp_path_factory: pytest.TempPathFactory) -> Installed:
    root = tmp_path_factory.mktemp("wheel")
    wheel = build_wheel(root)
    names = zipfile.ZipFile(wheel).namelist()
    assert {n.split("/")[0] for n in names} == {*PACKAGES, "nbv_workbench-0.1.0.dist-info"}
    statics = {n for n in names if n.startswith("app/static/")}
    assert {"app/static/index.html", "app/static/app.js", "app/static/style.css"} <= statics
    assert "nbv/__main__.py" in names and "nbv/import_path.py" in names

    venv = root / "venv"
    subprocess.run([sys.executable, "-m", "venv", "--without-pip", str(venv)], check=True, timeout=60)
    python = venv / "bin" / "python"
    pip = [sys.executable, "-m", "pip", "--python", str(python), "install", "--no-deps", "--no-index", "-q"]
    subprocess.run([*pip, str(wheel)], check=True, capture_output=True, timeout=120)
    site = Path(
        subprocess.run(
            [str(python), "-c", "import sysconfig; print(sysconfig.get_paths()['purelib'])"],
            check=True,
            capture_output=True,
            text=True,
        ).stdout.strip()
    )
    (site / "shared-venv.pth").write_text(shared_site_pth())

    lab = root / "lab"  # a lab's FastAPI project, with a planner of its own
    (lab / "app").mkdir(parents=True)
    (lab / "app" / "__init__.py").write_text(DECOY + "NAME = 'the lab app'\n")
    (lab / "planner").mkdir()
    (lab / "planner" / "__init__.py").write_text(DECOY + "raise ImportError('the lab planner')\n")
    (lab / "serve.toml").write_text(small_costs_toml())
    # where the names resolve from the lab's folder, found without importing the stack (scan, serve and bench
    # import it; the serve test's worker preload imports pinocchio): nbv, then app and planner as nbv has put them
    find = "import nbv, importlib.util as u; print(nbv.__file__, *(u.find_spec(n).origin for n in ('app', 'planner')))"
    assert_pinocchio = "; assert u.find_spec('pinocchio') is not None"
    found = subprocess.run(
        [str(python), "-c", find + assert_pinocchio],
        cwd=lab,
        env={k: v for k, v in os.environ.items() if not k.startswith("PYTHON")},
        check=True,
        capture_output=True,
        text=True,
    ).stdout.split()
    assert [Path(f) for f in found] == [site / f"{n}/__init__.py" for n in ("nbv", "app", "planner")]
    return Installed(python, venv / "bin" / "nbv", lab)


def test_python_m_nbv_scans_from_the_labs_folder(installed: Installed) -> None:
    """The working folder first on the path (python -m), and again on PYTHONPATH."""
    installed.marker.unlink(missing_ok=True)
    out = installed.lab / "scan"
    args = ["-m", "nbv", "scan", "--model", "l-block", "--views", "3", "--no-reachable", "--out", str(out)]
    installed.run(str(installed.python), *args, "--resolution", "0.02", on_pythonpath=True)
    metrics = json.loads((out / "metrics.json").read_text())
    assert len(metrics["iterations"]) == 3 and metrics["terminated"] == "max_views"
    assert metrics["final_coverage"] > 0.3
    assert not installed.marker.exists(), installed.marker.read_text()


def test_nbv_serve_from_the_labs_folder_runs_a_session_in_its_worker(installed: Installed) -> None:
    installed.marker.unlink(missing_ok=True)
    port = free_port()
    log = installed.lab / "serve.log"
    cmd = [str(installed.nbv), "serve", "--port", str(port), "--viser-port", "0", "--config", "serve.toml"]
    cmd += ["--data-dir", str(installed.lab / "data"), "--log-level", "warning"]
    with open(log, "wb") as out:
        proc = subprocess.Popen(cmd, cwd=installed.lab, env=installed.env(True), stdout=out, stderr=subprocess.STDOUT)
    try:
        with httpx.Client(base_url=f"http://127.0.0.1:{port}", timeout=60) as api:
            deadline = time.monotonic() + 60
            while True:
                try:
                    if api.get("/api/health").status_code == 200:
                        break
                except httpx.TransportError:
                    pass
                assert proc.poll() is None and time.monotonic() < deadline, log.read_text()[-3000:]
                time.sleep(0.1)
            sid = api.post("/api/sessions", json={"model": "l-block", "config": SMALL}).json()["id"]
            assert api.post(f"/api/sessions/{sid}/capture").status_code == 200, log.read_text()[-3000:]
            plan = api.post(f"/api/sessions/{sid}/plan")  # in the session's worker process
            assert plan.status_code == 200, plan.text
            assert api.get(f"/api/sessions/{sid}").json()["state"] == "planned"
        proc.send_signal(signal.SIGTERM)
        assert proc.wait(15) in (0, -signal.SIGTERM)  # uvicorn re-raises the signal once it has shut down
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.wait(15)
    assert "Traceback" not in log.read_text(), log.read_text()[-3000:]
    assert not installed.marker.exists(), installed.marker.read_text()


def test_nbv_bench_from_the_labs_folder(installed: Installed) -> None:
    """Two jobs on the local process pool (forkserver workers); Dask's spawned workers follow the same fixed path
    (tests/nbv/test_import_path.py starts a spawned child from a lab folder, and tests/nbv/test_bench_dask.py runs
    the Dask executor)."""
    installed.marker.unlink(missing_ok=True)
    out = installed.lab / "bench"
    args = ["bench", "--models", "l-block", "--planners", "projection", "--seeds", "2", "--views", "2"]
    args += ["--resolution", "0.02", "--no-reachable", "--out", str(out), "--executor", "local", "--jobs", "2"]
    installed.run(str(installed.nbv), *args, on_pythonpath=True, timeout=180)
    with open(out / "results.csv", newline="") as f:
        rows = list(csv.DictReader(f))
    assert sorted((r["seed"], r["iteration"]) for r in rows) == [("0", "1"), ("0", "2"), ("1", "1"), ("1", "2")]
    assert all(0.0 < float(r["coverage"]) <= 1.0 for r in rows)
    assert not installed.marker.exists(), installed.marker.read_text()
