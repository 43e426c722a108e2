"""Open a RealSense recording, stream it to its end, close: does ``pipeline.stop()`` ever kill the process?

librealsense 2.59 (pyrealsense2) aborted ("pure virtual method called") or segfaulted now and then in
``pipeline.stop()`` of a non-real-time playback, after :meth:`RealSenseCamera.stream` had read the recording to
its end (``tests/devices/drivers/test_realsense_stream.py``). Each trial is a child process that writes nothing:
it opens the recording, streams every frame (decoding each, as the move streamer does), closes the queue and the
camera, ``--cycles`` times. A child that dies by a signal is a crash.

    PYTHONPATH=$PWD .venv/bin/python benchmarks/crash_realsense_stop.py --trials 20 --cycles 5

Prints one line per crashed trial and the crash count (children, and cycles run).
"""

from __future__ import annotations

import argparse
import contextlib
import os
import signal
import subprocess
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
FRAMES = 25


def record(path: Path) -> None:
    """A recording like the stream test's: 80x60 frames at 30 fps stamped on the host clock (global time)."""
    import numpy as np

    from devices.drivers.rsrecord import write_depth_recording
    from planner.types import Intrinsics

    t0 = time.time() - 100.0
    stamps = [(t0 + i / 30) * 1000.0 for i in range(FRAMES)]
    depths = [np.full((60, 80), 0.3 + 0.01 * i, dtype=np.float32) for i in range(FRAMES)]
    k = Intrinsics(80, 60, 70.0, 72.0, 41.5, 28.5)
    write_depth_recording(
        path, depths, k, depth_unit=1e-4, fps=30, timestamps_ms=stamps, domains=["global_time"] * FRAMES
    )


def cycle(path: Path, capture: bool) -> int:
    """Open, stream to the end (and capture, if asked), close; the frames received."""
    from devices.drivers.realsense import RealSenseCamera, RealSenseConfig

    config = RealSenseConfig(width=80, height=60, fps=30, playback=str(path), min_depth=0.05, timeout_s=1.0)
    received = 0
    with RealSenseCamera(config) as camera:
        frames = camera.stream()
        deadline = time.monotonic() + 10.0
        while received < FRAMES and time.monotonic() < deadline:
            frame = frames.get(0.05)
            if frame is not None:
                frame.decode()
                received += 1
        frames.close()
        if capture:
            with contextlib.suppress(Exception):
                camera.capture()  # at the end of the recording: a CaptureError
    return received


def main() -> int:
    parser = argparse.ArgumentParser(description=(__doc__ or "").split("\n\n")[0])
    parser.add_argument("--trials", type=int, default=20, help="child processes")
    parser.add_argument("--cycles", type=int, default=5, help="open-stream-close cycles per child")
    parser.add_argument("--capture", action="store_true", help="also try a capture after the stream, before close")
    parser.add_argument("--child", default="", help=argparse.SUPPRESS)
    args = parser.parse_args()
    if args.child:
        for _ in range(args.cycles):
            got = cycle(Path(args.child), args.capture)
            print(f"received {got}", flush=True)
        return 0
    env = {**os.environ, "PYTHONPATH": str(ROOT), "OMP_NUM_THREADS": "1"}
    crashes, cycles = 0, 0
    with tempfile.TemporaryDirectory() as folder:
        path = Path(folder) / "move.db3"
        record(path)
        began = time.monotonic()
        for trial in range(args.trials):
            extra = ["--capture"] if args.capture else []
            child = [sys.executable, __file__, "--child", str(path), "--cycles", str(args.cycles), *extra]
            run = subprocess.run(child, env=env, capture_output=True, text=True, timeout=300)
            done = run.stdout.count("received")
            cycles += done
            short = [line for line in run.stdout.splitlines() if line != f"received {FRAMES}"]
            if run.returncode != 0:
                crashes += 1
                how = signal.Signals(-run.returncode).name if run.returncode < 0 else f"exit {run.returncode}"
                tail = run.stderr.strip().splitlines()[-1:] if run.stderr.strip() else []
                print(f"trial {trial}: {how} after {done} cycles {tail}", flush=True)
            elif short:
                print(f"trial {trial}: {short}", flush=True)
    print(
        f"crashes: {crashes}/{args.trials} children ({cycles} open-stream-close cycles completed, "
        f"{args.cycles} per child), {time.monotonic() - began:.0f} s"
    )
    return 0


if __name__ == "__main__":
    sys.exit(main())
