"""write a scan's recording: a zip that plays the session view by view offline, in any browser

``nbv record DATA_DIR/sessions/ID --out scan.zip`` replays the journaled session (workbench.journal's
``journal_timeline``: every view's plan re-made and checked as ``nbv replay`` does) and writes what
``GET /api/sessions/{id}/recording`` serves (app/scene/recording.py): unzip it and open ``index.html``, or serve
the folder with ``python -m http.server``. Used by ``nbv.cli`` as ``add_arguments(parser)`` / ``run(args) -> int``.
"""

from __future__ import annotations

import argparse
from pathlib import Path


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("journal", type=Path, metavar="JOURNAL_DIR", help="a session folder (DATA_DIR/sessions/ID)")
    parser.add_argument("--out", type=Path, required=True, metavar="FILE.zip", help="the zip to write")
    parser.add_argument(
        "--step-seconds", type=float, default=None, help="seconds of playback per view (default: the recording's)"
    )


def run(args: argparse.Namespace) -> int:
    from app.scene.recording import STEP_SECONDS, build_recording
    from workbench.journal import journal_timeline

    if args.out.suffix.lower() != ".zip":
        raise ValueError(f"--out {args.out}: the recording is a zip (name it FILE.zip)")
    step_seconds = STEP_SECONDS if args.step_seconds is None else float(args.step_seconds)
    if not step_seconds > 0:
        raise ValueError(f"--step-seconds {args.step_seconds}: must be > 0")
    steps, scene = journal_timeline(args.journal)
    # its files in one folder named as the zip (unzipping does not spill them into the current directory)
    built = build_recording(steps, scene, f"NBV scan {scene.session_id}", step_seconds, folder=args.out.stem)
    args.out.parent.mkdir(parents=True, exist_ok=True)
    tmp = args.out.with_name(args.out.name + ".part")
    tmp.write_bytes(built.data)
    tmp.replace(args.out)
    print(
        f"{args.out}: {built.views} views, {len(built.data) / 1e6:.2f} MB "
        f"(scene {built.scene_bytes / 1e6:.2f} MB), built in {built.seconds:.1f} s"
    )
    return 0
