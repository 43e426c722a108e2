"""planner/deferred_imports.py: open3d imported after ``planner`` leaves dash out until its plotly drawing is used,
and that drawing then works as open3d's own."""

from __future__ import annotations

import subprocess
import sys

SCRIPT = """
import sys
import planner
import open3d as o3d
from planner.deferred_imports import PLOTLY, DeferredPlotly

assert "dash" not in sys.modules and "plotly" not in sys.modules, "imported with open3d"
assert isinstance(sys.modules[PLOTLY], DeferredPlotly)
assert repr(sys.modules[PLOTLY]) == "<module 'open3d.visualization.draw_plotly'>"  # a dunder loads nothing
assert "dash" not in sys.modules

from open3d.visualization.draw_plotly import get_plotly_fig  # the stand-in's function, as a caller would take it
cloud = o3d.geometry.PointCloud(o3d.utility.Vector3dVector([[0.0, 0.0, 0.0], [1.0, 2.0, 3.0]]))
figure = get_plotly_fig([cloud])
assert "dash" in sys.modules and type(figure).__name__ == "Figure"
assert list(figure.data[0].x) == [0.0, 1.0] and list(figure.data[0].z) == [0.0, 3.0]
assert not isinstance(sys.modules[PLOTLY], DeferredPlotly)
for name in ("get_plotly_fig", "draw_plotly", "draw_plotly_server"):  # open3d's functions again, not the module
    function = getattr(o3d.visualization, name)
    assert callable(function) and function.__module__ == PLOTLY, name
assert o3d.visualization.draw_plotly is sys.modules[PLOTLY].draw_plotly
print("ok")
"""


def test_dash_loads_only_when_open3d_plotly_drawing_is_called() -> None:
    done = subprocess.run([sys.executable, "-c", SCRIPT], capture_output=True, text=True, timeout=120)
    assert done.returncode == 0, done.stderr
    assert done.stdout.strip() == "ok"


def test_defer_does_nothing_once_open3d_is_imported() -> None:
    script = (
        "import sys, open3d\n"
        "from planner.deferred_imports import PLOTLY, DeferredPlotly, defer\n"
        "before = sys.modules[PLOTLY]\n"
        "defer()\n"
        "assert sys.modules[PLOTLY] is before and not isinstance(before, DeferredPlotly)\n"
        "print('ok')\n"
    )
    done = subprocess.run([sys.executable, "-c", script], capture_output=True, text=True, timeout=120)
    assert done.returncode == 0, done.stderr
    assert done.stdout.strip() == "ok"
