"""The packages import only downward, no two files import each other (directly or in a circle), and importing
planner/ or workbench/ loads no web stack.

Layers, lowest first: planner < devices < workbench < app < nbv. Every import counts, at module level or
inside a function (a lazy import still ties the two files together); only ``if TYPE_CHECKING:`` imports,
which never run, are left out.
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
    typing_only = {
        id(inner)
        for node in ast.walk(tree)
        if isinstance(node, ast.If) and "TYPE_CHECKING" in ast.unparse(node.test)
        for stmt in node.body
        for inner in ast.walk(stmt)
    }
    out: set[str] = set()
    for node in ast.walk(tree):
        if id(node) in typing_only:  # annotations only: never imported at run time
            continue
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
    known["workbench.a"].write_text(
        "from typing import TYPE_CHECKING\nif TYPE_CHECKING:\n    import app.b\ndef f():\n    from app.b import g\n"
    )
    known["app.b"].write_text("from workbench import a\nfrom workbench.a import f\n")
    assert imports_of("workbench.a", known["workbench.a"], known) == {"app.b"}
    assert imports_of("app.b", known["app.b"], known) == {"workbench.a"}


@pytest.mark.parametrize(
    ("imports", "banned"),
    [
        ("planner, planner.planner, planner.registration", ("fastapi", "uvicorn", "viser", "open3d")),
        ("workbench, workbench.registry, workbench.session, workbench.journal.replay", WEB_STACK),
    ],
    ids=["planner-loads-no-heavy-stack", "workbench-loads-no-web-stack"],
)
def test_importing_a_lower_package_loads_no_stack_above_it(imports: str, banned: tuple[str, ...]) -> None:
    code = f"import sys, {imports}\nprint(','.join(m for m in {banned!r} if m in sys.modules))\n"
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    assert out.stdout.strip() == ""
