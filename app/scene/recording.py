"""A scan's recording: a zip that plays the session view by view offline, in any browser, with no server.

The scene is drawn step by step (``TimelineStep``, workbench/journal/timeline.py) by the same
:class:`~app.scene.drawing.SessionDrawing` a tab's viewer uses, into the scene of a private viser server that
nobody connects to, and recorded by viser's own serializer (``ViserServer.get_scene_serializer``): one step every
``STEP_SECONDS``, each with the plan's voxels, ellipsoids, candidates coloured by their score, the planner's
choice (``/nbv``), the approved view when it was another (``/selected``), the views so far and the cloud, and a
label naming the step. The zip holds::

    index.html     viser's client build (site-packages/viser/client/build) with the scene embedded
                   (window.__VISER_EMBED_DATA__, as viser's own ``as_html``) and a panel listing the steps'
                   plan, best view and score, the decision and the voxel counts, following the playback time
    scene.viser    the same scene as a file, for viser's ``?playbackPath=scene.viser`` players
    steps.json     the steps' summaries (``TimelineStep.summary``)

(the server's download puts them in one top-level folder, ``nbv-ID-recording/``, so unzipping makes a folder)

so ``index.html`` plays from the unzipped folder (file://) and from any static host (``python -m http.server``).
"""

from __future__ import annotations

import contextlib
import html
import io
import json
import socket
import time
import zipfile
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any, cast

import viser

from app.scene.drawing import SessionDrawing
from app.scene.geometry import DEFAULT_LAYERS
from app.scene.lighting import configure_lighting
from workbench import SceneData, TimelineStep, jsonable

STEP_SECONDS = 2.0
"""Seconds of playback per view."""
RECORDING_LAYERS = {**DEFAULT_LAYERS, "gizmo": False, "surface": False}
"""The layers a recording draws (a tab's defaults; no gizmo, no surface: a timeline step has none)."""


@dataclass(frozen=True)
class Recording:
    """A built recording: the zip's bytes, what went in, and how long it took (seconds)."""

    data: bytes
    views: int
    scene_bytes: int
    seconds: float


def _free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return int(s.getsockname()[1])


def record_scene(steps: Sequence[TimelineStep], now: SceneData, step_seconds: float = STEP_SECONDS) -> bytes:
    """The ``.viser`` bytes of ``steps`` drawn one after the other (``now``: the session's scene for what a step
    does not hold: mesh, plate, camera model). ValueError without a step."""
    if not steps:
        raise ValueError("recording: the session has no view to play")
    with contextlib.redirect_stdout(io.StringIO()):  # viser prints its address: nobody connects to this one
        server = viser.ViserServer(host="127.0.0.1", port=_free_port(), verbose=False)
    try:
        configure_lighting(server)
        server.initial_camera.position = (0.95, -0.8, 0.75)
        server.initial_camera.look_at = (0.0, 0.0, 0.08)
        serializer = server.get_scene_serializer()
        # the server stands in for a client: SessionDrawing uses only .scene and .atomic() of it
        drawing = SessionDrawing(cast(Any, server), dict(RECORDING_LAYERS), lambda index: None, lambda pose: None)
        n = len(steps)
        for step in steps:
            drawing.update(step.scene_data(now))
            server.scene.add_label(
                "/recording/step", _caption(step, n), position=(0.0, -1.25 * now.plate_radius, 0.0),
                font_screen_scale=0.8,
            )  # fmt: skip
            serializer.insert_sleep(step_seconds)
        return serializer.serialize()
    finally:
        with contextlib.redirect_stdout(io.StringIO()):
            server.stop()


def _caption(step: TimelineStep, views: int) -> str:
    """The step's label in the 3D view: ``view 3 of 10 · best #45 F 0.42 · approve #45``."""
    s = step.summary()
    best = s["best"]
    parts = [f"view {step.view} of {views}"]
    parts.append("no plan" if best is None else f"best #{best['index']} F {best['score']:.3g}")
    d = s["decision"]
    if d is not None:
        parts.append(f"{d['kind']} custom pose" if d["custom"] else f"{d['kind']} #{d['index']}")
    return " · ".join(parts)


def build_recording(
    steps: Sequence[TimelineStep], now: SceneData, title: str, step_seconds: float = STEP_SECONDS, folder: str = ""
) -> Recording:
    """The zip of a recording of ``steps`` (see the module docstring). ValueError without a step. ``folder``: the
    zip's one top-level folder its files are in (unzipping then makes that folder, not loose files); "": none."""
    t0 = time.perf_counter()
    scene = record_scene(steps, now, step_seconds)
    summaries = [jsonable(step.summary()) for step in steps]
    buf = io.BytesIO()
    files = [
        ("index.html", page(scene, summaries, title, step_seconds).encode("utf-8"), zipfile.ZIP_DEFLATED),
        ("scene.viser", scene, zipfile.ZIP_STORED),  # zstd inside already
        ("steps.json", json.dumps({"title": title, "step_seconds": step_seconds, "steps": summaries}).encode(), 8),
    ]
    with zipfile.ZipFile(buf, "w") as z:
        for name, data, method in files:
            info = zipfile.ZipInfo(f"{folder}/{name}" if folder else name, date_time=time.localtime()[:6])
            info.compress_type = method
            info.external_attr = 0o644 << 16  # readable by a static server run as anyone
            z.writestr(info, data)
    return Recording(buf.getvalue(), len(steps), len(scene), time.perf_counter() - t0)


def client_build() -> Path:
    """viser's static client (one self-contained index.html), the player of the recording."""
    return Path(viser.__file__).parent / "client" / "build" / "index.html"


def page(scene: bytes, steps: list[Any], title: str, step_seconds: float) -> str:
    """viser's client build with ``scene`` embedded and the steps' panel (follows the playback bar's time)."""
    import base64

    client = client_build().read_text(encoding="utf-8")
    data = base64.b64encode(scene).decode("ascii")
    head = (
        f'<script>window.__VISER_EMBED_DATA__="{data}";window.__VISER_EMBED_CONFIG__={{darkMode:false}};</script>'
        f"<script>window.NBV_STEPS={json.dumps(steps)};window.NBV_STEP_SECONDS={step_seconds!r};</script>"
        f"<style>{_PANEL_CSS}</style>"
    )
    body = f'<div id="nbv-steps" data-testid="recording-steps"><b>{html.escape(title)}</b><div id="nbv-now"></div>'
    body += f'<table id="nbv-table"></table></div><script>{_PANEL_JS}</script>'
    at = client.index("</head>")
    client = client[:at] + head + client[at:]
    end = client.rindex("</body>")
    return client[:end] + body + client[end:]


_PANEL_CSS = """
#nbv-steps{position:fixed;left:8px;top:8px;z-index:5;background:rgba(255,255,255,.92);border:1px solid #ccd;
border-radius:4px;padding:6px 8px;font:12px system-ui,sans-serif;max-height:60vh;overflow:auto}
#nbv-steps td{padding:1px 5px}#nbv-steps tr.on{background:#ffe9a8;font-weight:600}
"""

_PANEL_JS = r"""
(function () {
  const steps = window.NBV_STEPS, dt = window.NBV_STEP_SECONDS;
  const rows = steps.map((s) => {
    const b = s.best ? `#${s.best.index} F ${s.best.score.toPrecision(3)}` : "no plan";
    const d = s.decision ? (s.decision.custom ? `${s.decision.kind} custom` : `${s.decision.kind} #${s.decision.index}`) : "–";
    const cov = s.coverage === null ? "–" : (100 * s.coverage).toFixed(1) + " %";
    return `<tr data-view="${s.view}"><td>view ${s.view}</td><td>best ${b}</td><td>${d}</td>` +
      `<td>occ ${s.voxels.occupied} · fr ${s.voxels.frontier}</td><td>${cov}</td></tr>`;
  });
  document.getElementById("nbv-table").innerHTML = rows.join("");
  let shown = 0;
  window.NBV_SHOWN = [];  // every view the panel named, in order (the playback loops: 1..n, 1..n, ...)
  function tick() {
    // the playback bar's time: viser's NumberInput next to its slider (the recording is one step per dt)
    const input = document.querySelector(".mantine-NumberInput-input");
    if (!input) return;
    const t = parseFloat(input.value);
    if (!isFinite(t)) return;
    const view = Math.min(steps.length, Math.floor(t / dt + 1e-6) + 1);
    if (view === shown) return;
    shown = view;
    window.NBV_SHOWN.push(view);
    document.getElementById("nbv-now").textContent = `view ${view} of ${steps.length}`;
    for (const tr of document.querySelectorAll("#nbv-table tr")) tr.classList.toggle("on", Number(tr.dataset.view) === view);
  }
  setInterval(tick, 100);
})();
"""
