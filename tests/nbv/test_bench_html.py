"""report.html: the Markdown subset of summary.md as HTML, plots inline; the mesh payload a worker gets."""

from __future__ import annotations

import base64
from pathlib import Path

import numpy as np
import pytest

from nbv.bench_html import markdown_to_html, report_html
from workbench.evaluation.runs import MeshPayload

SUMMARY = """# nbv bench

Models: `a|b` and <c>.

## Coverage against the ceiling

| planner | at view 2 |
| --- | ---: |
| projection | 0.9 ± 0.1 |
| x \\| y | – |

## Total planning time (s)

text
"""


def test_markdown_subset() -> None:
    page = markdown_to_html(SUMMARY)
    assert "<h1>nbv bench</h1>" in page and "<h2>Coverage against the ceiling</h2>" in page
    assert "<p>Models: <code>a|b</code> and &lt;c&gt;.</p>" in page
    assert '<tr><th>planner</th><th class="num">at view 2</th></tr>' in page
    assert '<tr><td>projection</td><td class="num">0.9 ± 0.1</td></tr>' in page
    assert "<td>x | y</td>" in page  # an escaped pipe stays inside its cell


def test_report_embeds_the_plots_before_the_timings(tmp_path: Path) -> None:
    png = b"\x89PNG\r\n\x1a\nfake"
    (tmp_path / "ratio.png").write_bytes(png)
    page = report_html(SUMMARY, [tmp_path / "ratio.png"])
    assert page.startswith("<!DOCTYPE html>") and page.rstrip().endswith("</html>")
    data = base64.b64encode(png).decode()
    assert f'<img alt="ratio" src="data:image/png;base64,{data}">' in page
    assert page.index("<h2>Plots</h2>") < page.index("<h2>Total planning time (s)</h2>")
    assert 'src="http' not in page and "<link" not in page  # self-contained


def test_mesh_payload_round_trip_and_bad_input() -> None:
    v = np.array([[0.0, 0, 0], [1, 0, 0], [0, 1, 0]])
    f = np.array([[0, 1, 2]])
    mesh = MeshPayload(v, f).to_trimesh()
    assert np.array_equal(mesh.vertices, v) and np.array_equal(mesh.faces, f)
    assert MeshPayload.of(mesh).nbytes == v.nbytes + f.nbytes
    with pytest.raises(ValueError, match="faces"):
        MeshPayload(v, np.array([[0, 1, 3]]))
    with pytest.raises(ValueError, match="vertices"):
        MeshPayload(np.array([[0.0, np.nan, 0]]), np.array([[0, 0, 0]]))
