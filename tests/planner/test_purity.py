"""planner/ stays pure: importing it loads none of the web or 3D stack."""

import subprocess
import sys


def test_import_planner_loads_no_heavy_stack() -> None:
    code = (
        "import sys, planner, planner.planner, planner.registration\n"
        "heavy = [m for m in ('fastapi', 'uvicorn', 'viser', 'open3d') if m in sys.modules]\n"
        "print(','.join(heavy))\n"
    )
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    assert out.stdout.strip() == ""
