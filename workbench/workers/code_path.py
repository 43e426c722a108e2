"""Whether worker processes would run other code than the process that starts them.

Session workers and ``nbv bench``'s run workers are forks of a forkserver that preloaded the project's modules. On
Python 3.11 the forkserver is a new interpreter started with ``-c``, so its ``sys.path`` begins with its working
directory, and it imports its preloads with that path (``multiprocessing.forkserver.main`` takes the parent's path
and drops it; each child gets it after the fork, when the preloaded modules are already there). Started in a
directory that holds another copy of the project, the parent runs one copy's code and every worker the directory's
preloaded modules, even with ``PYTHONPATH`` naming the first: a benchmark of one version measured with another's
planner, silently.
:func:`shadowing_code` tells, so the commands that start workers can refuse with a clear message instead.
"""

from __future__ import annotations

import importlib.util
from pathlib import Path

PACKAGES = ("planner", "devices", "workbench", "app", "nbv")
"""The project's top-level packages."""


def shadowing_code(cwd: Path | None = None) -> str | None:
    """A one-line reason when ``cwd`` (default: the working directory) holds a package named like one of the
    project's that is not the one this process imports (another checkout, or an unrelated package of that name: the
    workers would import it), else None."""
    here = (cwd or Path.cwd()).resolve()
    for name in PACKAGES:
        local = here / name / "__init__.py"
        if not local.is_file():
            continue
        spec = importlib.util.find_spec(name)
        origin = None if spec is None or spec.origin is None else Path(spec.origin).resolve()
        if origin is not None and origin != local.resolve():
            return (
                f"the working directory holds a package {name!r} ({local.parent}) other than the one this command "
                f"runs ({origin.parent}), and the worker processes would import the directory's: run it from "
                f"{origin.parent.parent} (or a directory without such a package), or with PYTHONPATH={here} if the "
                "directory is the checkout you mean"
            )
    return None
