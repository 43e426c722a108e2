"""The documentation: the site builds strictly, the README and the pages stay short, and neither the docs nor the
product code name the development history (a round, session, issue or phase by number) instead of the topic.

(tests/app/test_docs.py is another thing: the API's /docs page served offline.)"""

from __future__ import annotations

import os
import re
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
DOCS = ROOT / "docs"
PRODUCT = ("planner", "devices", "workbench", "app", "nbv")
TEXT_SUFFIXES = {".md", ".txt", ".py", ".js", ".html", ".css", ".svg", ".toml", ".json", ".csv"}
README_MAX_LINES = 150
PAGE_MAX_BYTES = 40_000
HISTORY = re.compile(r"(round|session|issue|phase) [0-9]+", re.IGNORECASE)
"""A development label: 'round 3', 'session 31', 'issue 25', 'phase 2'. Docs say what and why, by topic."""


def text_files(top: Path) -> list[Path]:
    """Every text file under ``top`` (the suffixes above), caches left out, in a stable order."""
    return sorted(
        p for p in top.rglob("*") if p.is_file() and p.suffix in TEXT_SUFFIXES and "__pycache__" not in p.parts
    )


def history_labels(path: Path) -> list[str]:
    """``"line: text"`` for each line of ``path`` that carries a development label."""
    lines = path.read_text(encoding="utf-8", errors="replace").splitlines()
    return [f"{i}: {line.strip()[:120]}" for i, line in enumerate(lines, 1) if HISTORY.search(line)]


def test_the_history_pattern_catches_labels_and_spares_prose() -> None:
    for label in ("issue 25's sixth round", "Session 31", "phase 2a", "ROUND 3", "(issue 5)"):
        assert HISTORY.search(label), label
    for prose in ("a session's journal", "the tenth view", "round-trip 3 times", "issue-free", "session_id 4"):
        assert not HISTORY.search(prose), prose


def test_history_labels_are_found_with_their_line(tmp_path: Path) -> None:
    page = tmp_path / "page.md"
    page.write_text("# A page\n\nMeasured in session 12.\nA session's view.\n", encoding="utf-8")
    assert history_labels(page) == ["3: Measured in session 12."]


@pytest.mark.slow  # about 2 s: a process that imports mkdocs and the theme and builds every page
def test_the_site_builds_strictly(tmp_path: Path) -> None:
    """mkdocs.yml's validation makes a broken link or anchor, or a page missing from the nav, a warning, and strict
    makes a warning fail the build."""
    env = {**os.environ, "NO_MKDOCS_2_WARNING": "1"}
    command = [sys.executable, "-m", "mkdocs", "build", "--strict", "--config-file", str(ROOT / "mkdocs.yml")]
    built = subprocess.run(
        [*command, "--site-dir", str(tmp_path / "site")],
        cwd=ROOT,
        env=env,
        capture_output=True,
        text=True,
        timeout=120,
    )
    problems = [line for line in built.stderr.splitlines() if line.startswith(("WARNING", "ERROR"))]
    assert built.returncode == 0 and not problems, "\n".join(problems) or built.stderr[-3000:]
    site = tmp_path / "site"
    for page in ("index.html", "getting-started.html", "cli.html", "rest.html", "bench/index.html"):
        assert (site / page).is_file(), page
    home = (site / "index.html").read_text(encoding="utf-8")
    assert "fonts.googleapis" not in home  # the theme loads no fonts from the internet


def test_the_readme_is_short() -> None:
    lines = (ROOT / "README.md").read_text(encoding="utf-8").splitlines()
    assert len(lines) <= README_MAX_LINES, f"README.md has {len(lines)} lines (at most {README_MAX_LINES})"


@pytest.mark.parametrize("page", sorted(DOCS.rglob("*.md")), ids=lambda p: str(p.relative_to(DOCS)))
def test_each_docs_page_is_at_most_40_kb(page: Path) -> None:
    size = page.stat().st_size
    assert size <= PAGE_MAX_BYTES, f"docs/{page.relative_to(DOCS)} is {size} bytes: split it by topic"


@pytest.mark.parametrize("path", text_files(DOCS), ids=lambda p: str(p.relative_to(DOCS)))
def test_docs_name_no_development_history(path: Path) -> None:
    found = history_labels(path)
    assert not found, f"docs/{path.relative_to(DOCS)}:\n" + "\n".join(found)


@pytest.mark.parametrize("package", PRODUCT)
def test_product_code_names_no_development_history(package: str) -> None:
    found = [f"{p.relative_to(ROOT)}:{hit}" for p in text_files(ROOT / package) for hit in history_labels(p)]
    assert not found, "\n".join(found)
