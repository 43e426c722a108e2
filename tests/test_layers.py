"""The packages import only downward, no two files import each other (directly or in a circle), and importing
planner/ or workbench/ loads no web stack.

Layers, lowest first: planner < devices < workbench < app < nbv. Every import counts, at module level, inside a
function (a lazy import still ties the two files together) or under ``if TYPE_CHECKING:`` (an annotation that
names a module ties the two files as much as a call does). The web layer, the command line and the benchmarks use
the workbench through its public names only (``workbench.__all__`` and its sub-packages' ``__all__``), and the
benchmarks import the library, never the command line.
"""

from __future__ import annotations

import ast
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
LAYERS = ("planner", "devices", "workbench", "app", "nbv")
WEB_STACK = ("fastapi", "uvicorn", "viser", "starlette")


def modules() -> dict[str, Path]:
    found = {}
    for package in LAYERS:
        for path in sorted((ROOT / package).rglob("*.py")):
            parts = path.relative_to(ROOT).with_suffix("").parts
            name = ".".join(parts[:-1] if parts[-1] == "__init__" else parts)
            found[name] = path
    return found


def imports_of(name: str, path: Path, known: dict[str, Path]) -> set[str]:
    """The project modules ``name`` imports (``from a.b import c`` counts as a.b.c when that is a module)."""
    tree = ast.parse(path.read_text(), filename=str(path))
    package = name if path.name == "__init__.py" else name.rpartition(".")[0]
    out: set[str] = set()
    for node in ast.walk(tree):  # TYPE_CHECKING blocks included
        if isinstance(node, ast.Import):
            targets = [alias.name for alias in node.names]
        elif isinstance(node, ast.ImportFrom):
            base = node.module or ""
            if node.level:
                base = ".".join(
                    package.split(".")[: len(package.split(".")) - node.level + 1] + ([base] if base else [])
                )
            names = [f"{base}.{alias.name}" for alias in node.names]
            # ``from pkg import module`` ties to the module; ``from pkg import name`` to the package itself
            targets = [n if n in known else base for n in names]
        else:
            continue
        for target in targets:
            while target and target not in known:
                target = target.rpartition(".")[0]
            if target and target != name:
                out.add(target)
    return out


def graph() -> dict[str, set[str]]:
    known = modules()
    return {name: imports_of(name, path, known) for name, path in known.items()}


def test_packages_import_only_downward() -> None:
    wrong = []
    for name, targets in graph().items():
        rank = LAYERS.index(name.split(".")[0])
        for target in targets:
            if LAYERS.index(target.split(".")[0]) > rank:
                wrong.append(f"{name} -> {target}")
    assert wrong == []


def test_no_import_circles_between_files() -> None:
    g = graph()
    index: dict[str, int] = {}
    low: dict[str, int] = {}
    stack: list[str] = []
    on_stack: set[str] = set()
    circles: list[list[str]] = []

    def visit(v: str) -> None:  # Tarjan's strongly connected components
        index[v] = low[v] = len(index)
        stack.append(v)
        on_stack.add(v)
        for w in sorted(g[v]):
            if w not in index:
                visit(w)
                low[v] = min(low[v], low[w])
            elif w in on_stack:
                low[v] = min(low[v], index[w])
        if low[v] == index[v]:
            component = []
            while True:
                w = stack.pop()
                on_stack.discard(w)
                component.append(w)
                if w == v:
                    break
            if len(component) > 1:
                circles.append(sorted(component))

    for v in sorted(g):
        if v not in index:
            visit(v)
    assert circles == []


def test_the_check_sees_a_circle_and_an_upward_import(tmp_path: Path) -> None:
    """The checker itself: it finds what it is for."""
    known = {"workbench.a": tmp_path / "a.py", "app.b": tmp_path / "b.py"}
    known["workbench.a"].write_text("def f():\n    from app.b import g\n")
    known["app.b"].write_text("from workbench import a\nfrom workbench.a import f\n")
    assert imports_of("workbench.a", known["workbench.a"], known) == {"app.b"}
    assert imports_of("app.b", known["app.b"], known) == {"workbench.a"}


def test_the_check_counts_type_checking_imports(tmp_path: Path) -> None:
    """An import under ``if TYPE_CHECKING:`` ties the files too (a circle between two files once hid behind one)."""
    known = {"workbench.a": tmp_path / "a.py", "workbench.b": tmp_path / "b.py"}
    known["workbench.a"].write_text(
        "from typing import TYPE_CHECKING\nif TYPE_CHECKING:\n    from workbench.b import B\n"
    )
    known["workbench.b"].write_text("import workbench.a\n")
    assert imports_of("workbench.a", known["workbench.a"], known) == {"workbench.b"}
    assert imports_of("workbench.b", known["workbench.b"], known) == {"workbench.a"}


PUBLIC_PACKAGES = ("workbench", "workbench.evaluation", "workbench.journal", "workbench.surface")
"""The workbench packages whose ``__all__`` is an API for app/, nbv/ and benchmarks/."""


def public_names() -> dict[str, set[str]]:
    import importlib

    return {name: set(importlib.import_module(name).__all__) for name in PUBLIC_PACKAGES}


def workbench_imports(directory: str) -> list[tuple[str, str, str]]:
    """(file, module, name) of every ``from workbench... import name`` and ``import workbench...`` in a folder."""
    found = []
    for path in sorted((ROOT / directory).rglob("*.py")):
        rel = str(path.relative_to(ROOT))
        for node in ast.walk(ast.parse(path.read_text(), filename=rel)):
            if isinstance(node, ast.ImportFrom) and (node.module or "").split(".")[0] == "workbench":
                found += [(rel, node.module or "", alias.name) for alias in node.names]
            elif isinstance(node, ast.Import):
                found += [(rel, a.name, "") for a in node.names if a.name.split(".")[0] == "workbench"]
    return found


@pytest.mark.parametrize("directory", ["app", "nbv", "benchmarks"])
def test_the_upper_layers_use_only_the_public_names_of_the_workbench(directory: str) -> None:
    public = public_names()
    wrong = [
        f"{rel}: from {module} import {name}"
        for rel, module, name in workbench_imports(directory)
        if module not in public or name not in public[module]
    ]
    assert wrong == []


def test_the_public_names_exist_and_are_sorted() -> None:
    import importlib

    for package, names in public_names().items():
        module = importlib.import_module(package)
        assert [n for n in names if not hasattr(module, n)] == []
        assert list(module.__all__) == sorted(module.__all__, key=lambda n: (not n.isupper(), n))


def test_benchmarks_import_the_library_never_the_command_line() -> None:
    wrong = []
    for path in sorted((ROOT / "benchmarks").glob("*.py")):
        for node in ast.walk(ast.parse(path.read_text())):
            modules = [a.name for a in node.names] if isinstance(node, ast.Import) else []
            if isinstance(node, ast.ImportFrom):
                modules = [node.module or ""]
            wrong += [f"{path.name}: {m}" for m in modules if m.split(".")[0] in ("nbv", "benchmarks")]
    assert wrong == []


def test_the_workbench_keeps_at_most_twelve_modules_at_its_top() -> None:
    top = sorted(p.name for p in (ROOT / "workbench").glob("*.py"))
    assert len(top) <= 12, top


@pytest.mark.parametrize(
    ("imports", "banned"),
    [
        ("planner, planner.planner, planner.registration", ("fastapi", "uvicorn", "viser", "open3d")),
        ("workbench, workbench.registry.registry, workbench.session.session, workbench.journal.check", WEB_STACK),
    ],
    ids=["planner-loads-no-heavy-stack", "workbench-loads-no-web-stack"],
)
def test_importing_a_lower_package_loads_no_stack_above_it(imports: str, banned: tuple[str, ...]) -> None:
    code = f"import sys, {imports}\nprint(','.join(m for m in {banned!r} if m in sys.modules))\n"
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    assert out.stdout.strip() == ""


def test_docs_architecture_lists_every_workbench_module() -> None:
    """docs/architecture.md's tree names every module of workbench/ (its folder and file name), and nothing more."""
    import re

    text = (ROOT / "docs" / "architecture.md").read_text()
    tree = text[text.index("```\nworkbench/\n") :]
    tree = tree[: tree.index("```", 4)]
    listed, folder = set(), ""
    for line in tree.splitlines()[1:]:
        match = re.match(r"^  (  )?([a-z_]+(?:\.py|/))", line)
        if match is None:
            continue
        name = match.group(2)
        if name.endswith("/"):
            folder = name
        else:
            listed.add((folder if match.group(1) else "") + name)
    actual = {
        str(p.relative_to(ROOT / "workbench"))
        for p in (ROOT / "workbench").rglob("*.py")
        if not (p.name == "__init__.py" and p.parent != ROOT / "workbench")
    }
    assert sorted(actual - listed) == [] and sorted(listed - actual) == []
