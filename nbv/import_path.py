"""Our packages come from where ``nbv`` was installed, never from the user's working folder or ``PYTHONPATH``.

The tool's top-level packages (``planner``, ``devices``, ``workbench``, ``app``, ``nbv``) have common names: a lab's
own FastAPI project usually has an ``app/`` package, and a folder of experiments may hold a ``planner/``. Python
puts such folders ahead of the installed tool:

- this process: ``python -m nbv`` starts with the working directory first on ``sys.path``, and every
  ``PYTHONPATH`` entry comes before site-packages; ``import app.settings`` then finds the lab's ``app``;
- the forkserver that the server's session workers and ``nbv bench``'s local runs fork from: on Python 3.11 it is
  a new interpreter started with ``-c``, so its ``sys.path`` begins with the working directory and the
  ``PYTHONPATH`` entries, and it imports its preloads (our modules) with that path
  (``multiprocessing.forkserver.main`` ignores the parent's path; each child gets it only after the fork, when the
  preloaded modules are already there);
- spawned children (the bench's pool where there is no forkserver, the Dask workers of a ``LocalCluster``) set the
  parent's ``sys.path`` before they import anything of ours, so they follow this process.

:func:`prefer_installed_packages`, called by ``nbv/__init__`` before anything imports our other packages (the
``nbv`` console script and ``python -m nbv`` both import ``nbv`` first), acts only when a folder actually holds a
package or module named like ours that is not ours (nothing changes when run from the checkout itself):

- in this process, the shadowing ``sys.path`` entries move to just after the folder ``nbv`` was found in
  (inserted where the first of them was, if that folder is not on ``sys.path``: an editable install's finder),
  so the user's other modules there stay importable;
- for child interpreters: ``PYTHONSAFEPATH=1`` when the working directory shadows (a ``-c`` interpreter then does
  not put it first), and the shadowing entries are dropped from ``PYTHONPATH`` (a forkserver's workers get them
  back, behind ours, with this process's ``sys.path`` after the fork).

Not covered: a folder with its own ``nbv`` package shadows ``python -m nbv`` itself (use the ``nbv`` command), and
an interpreter started with ``-E`` passes that on to its children, which then ignore ``PYTHONSAFEPATH``.
``nbv serve`` hands uvicorn the app object, not an import string, so uvicorn's ``app_dir`` adds no folder.
"""

from __future__ import annotations

import os
import sys
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from importlib.machinery import all_suffixes
from pathlib import Path

PACKAGES = ("planner", "devices", "workbench", "app", "nbv")
"""The tool's top-level packages."""


@dataclass(frozen=True)
class PathFix:
    """What :func:`plan_fix` found: the new ``sys.path``, the environment changes for child interpreters (a value
    of None: remove the variable) and the entries that shadowed ours (empty: nothing to do)."""

    sys_path: list[str]
    environ: dict[str, str | None] = field(default_factory=dict)
    shadowing: list[str] = field(default_factory=list)


def _dir(entry: str, cwd: Path) -> Path | None:
    """The resolved folder of a path entry ('' is the working directory), None when it is not a folder."""
    try:
        folder = (cwd / entry if entry else cwd).resolve()
    except OSError:
        return None
    return folder if folder.is_dir() else None


def holds_ours(folder: Path, names: Sequence[str] = PACKAGES) -> bool:
    """Whether ``folder`` holds a regular package or a module named like one of ``names`` (a folder without
    ``__init__.py`` is only a namespace portion: a regular package later on the path wins over it)."""
    for name in names:
        if (folder / name / "__init__.py").is_file():
            return True
        if any((folder / f"{name}{suffix}").is_file() for suffix in all_suffixes()):
            return True
    return False


def _shadowing(entries: Sequence[str], root: Path, cwd: Path) -> list[str]:
    """The entries, before the first that is ``root``, whose folder holds a package named like ours."""
    found: list[str] = []
    for entry in entries:
        folder = _dir(entry, cwd)
        if folder is None:
            continue
        if folder == root:
            break
        if holds_ours(folder):
            found.append(entry)
    return found


def plan_fix(sys_path: Sequence[str], environ: Mapping[str, str], cwd: Path, root: Path) -> PathFix:
    """The path fix for a process whose ``sys.path`` is ``sys_path``, environment ``environ`` and working directory
    ``cwd``, with our packages installed in ``root`` (the folder holding ``nbv/``). Pure: changes nothing."""
    root = root.resolve()
    cwd = cwd.resolve()
    bad = _shadowing(sys_path, root, cwd)
    new_path = list(sys_path)
    if bad:
        kept = [e for e in sys_path if e not in bad]
        on_path = [i for i, e in enumerate(kept) if _dir(e, cwd) == root]
        if on_path:
            at = on_path[0] + 1
        else:  # found by a meta-path finder (an editable install): our folder goes where the first shadow was
            at = sum(1 for e in sys_path[: sys_path.index(bad[0])] if e not in bad)
            kept.insert(at, str(root))
            at += 1
        new_path = kept[:at] + bad + kept[at:]
    environ_changes: dict[str, str | None] = {}
    cwd_shadows = cwd != root and holds_ours(cwd)
    if cwd_shadows and environ.get("PYTHONSAFEPATH") != "1":
        environ_changes["PYTHONSAFEPATH"] = "1"
    python_path = [e for e in environ.get("PYTHONPATH", "").split(os.pathsep) if e]
    bad_env = _shadowing(python_path, root, cwd)
    if bad_env:
        rest = [e for e in python_path if e not in bad_env]
        environ_changes["PYTHONPATH"] = os.pathsep.join(rest) if rest else None
    named = [*bad, *bad_env, *([str(cwd)] if cwd_shadows else [])]
    shadowing: list[str] = list(dict.fromkeys(named))
    return PathFix(new_path, environ_changes, shadowing)


def prefer_installed_packages() -> PathFix:
    """Apply :func:`plan_fix` to this process (``sys.path`` and ``os.environ``); returns what it did."""
    root = Path(__file__).resolve().parent.parent
    fix = plan_fix(sys.path, os.environ, Path.cwd(), root)
    if fix.shadowing:
        sys.path[:] = fix.sys_path
        for key, value in fix.environ.items():
            if value is None:
                os.environ.pop(key, None)
            else:
                os.environ[key] = value
    return fix
