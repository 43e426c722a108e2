"""open3d's plotly drawing, which we never call, imported when first used instead of with open3d.

Every process of the tool (the server, a session's worker, the CLI, a bench's workers) imports open3d.
``import open3d`` imports its plotly drawing module (``open3d.visualization.draw_plotly``), which imports dash,
plotly, flask and IPython: half of open3d's import time (measured on the 2-core machine: ``import open3d`` 0.93-1.01
-> 0.42-0.56 CPU-s).

:func:`defer` (run by ``planner/__init__.py``, so before any of our modules imports open3d) puts in ``sys.modules``
for ``open3d.visualization.draw_plotly`` a stand-in whose three functions (``get_plotly_fig``, ``draw_plotly``,
``draw_plotly_server``, which ``open3d.visualization`` re-exports) import the real module when called, put the real
functions back in ``open3d.visualization`` and run them; any other public name asked of the stand-in loads it too.
Nothing changes where open3d or that module was imported already.

(networkx, which trimesh imports for graph functions it runs only on request, was tried the same way with the
standard library's ``importlib.util.LazyLoader``: ``trimesh.base`` reads ``networkx.Graph`` at its import, which
loads it at once.)
"""

from __future__ import annotations

import importlib
import sys
import threading
import types
from collections.abc import Callable
from typing import Any

PLOTLY = "open3d.visualization.draw_plotly"
"""open3d's drawing module that imports dash."""
PLOTLY_NAMES = ("get_plotly_fig", "draw_plotly", "draw_plotly_server")
"""What ``open3d.visualization`` imports from it."""
_LOADING = threading.Lock()
"""One thread replaces the stand-in; another that asks meanwhile gets the real module."""


class DeferredPlotly(types.ModuleType):
    """Stands in for ``open3d.visualization.draw_plotly`` until one of its names is used."""

    def __getattr__(self, name: str) -> Any:
        """A public name the stand-in does not have: the real module's. Dunder names (``__file__``, ``__path__``,
        asked by the import system, ``repr`` and ``inspect``) are not loaded for."""
        if name.startswith("__"):
            raise AttributeError(name)
        return getattr(load_plotly(), name)


def load_plotly() -> types.ModuleType:
    """The real ``open3d.visualization.draw_plotly``, imported now (dash with it) in place of the stand-in; its
    functions put back in ``open3d.visualization`` (importing a submodule sets the parent's attribute of its name
    to the module, where open3d has the function ``draw_plotly``)."""
    with _LOADING:
        current = sys.modules.get(PLOTLY)
        if current is not None and not isinstance(current, DeferredPlotly):
            return current
        sys.modules.pop(PLOTLY, None)
        real = importlib.import_module(PLOTLY)
        visualization = sys.modules.get("open3d.visualization")
        if visualization is not None:
            for name in PLOTLY_NAMES:
                setattr(visualization, name, getattr(real, name))
        return real


def _deferred(name: str) -> Callable[..., Any]:
    def call(*args: Any, **kwargs: Any) -> Any:
        return getattr(load_plotly(), name)(*args, **kwargs)

    call.__name__ = call.__qualname__ = name
    call.__doc__ = f"open3d.visualization.{name}: imports open3d's plotly drawing module (and dash) on this call."
    return call


def defer() -> None:
    """Install the stand-in (see the module docstring); idempotent, nothing where open3d is imported already."""
    if "open3d" in sys.modules or PLOTLY in sys.modules:
        return
    stand_in = DeferredPlotly(PLOTLY, "stands in for open3d's plotly drawing until it is used")
    for name in PLOTLY_NAMES:
        setattr(stand_in, name, _deferred(name))
    sys.modules[PLOTLY] = stand_in
