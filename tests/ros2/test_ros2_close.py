"""Closing a ROS 2 camera while depth images stream in must not crash the process.

A cyclonedds reader left to the cyclic garbage collector kept its DDS reader while its listener's ctypes thunk was
freed: the next sample segfaulted the process (see ``devices/drivers/ros2/dds.py``). Here a publisher process sends
640x480 depth images at 30 Hz over loopback, and a child process opens a camera, streams (a thread of ours decoding
frames), closes it mid-stream and collects garbage, 20 times, on a participant the cell's other devices keep alive.
A crash is the child's signal in a failed assertion, not a dead test worker.
"""

from __future__ import annotations

import os
import signal
import subprocess
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]
SCRIPT = ROOT / "benchmarks" / "crash_ros2_close.py"


def test_closing_a_streaming_camera_twenty_times_leaves_the_process_alive_and_no_reader_behind() -> None:
    domain = 1 + (os.getpid() * 11 + 3) % 200
    env = {**os.environ, "PYTHONPATH": str(ROOT), "OMP_NUM_THREADS": "1"}
    me = [sys.executable, str(SCRIPT), "--domain", str(domain)]
    publisher = subprocess.Popen([*me, "--role", "publish"], env=env, stdin=subprocess.PIPE, stdout=subprocess.PIPE)
    # started together: the child's first camera waits (up to 3 s) for the publisher's first CameraInfo
    child = subprocess.Popen(
        [*me, "--role", "consume", "--closes", "20", "--hold", "0.04", "--collect"],
        env=env,
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
    )
    try:
        out, err = child.communicate(timeout=60)
    finally:
        child.kill()
        assert publisher.stdin is not None
        publisher.stdin.close()
        publisher.wait(timeout=10)
    died = f"killed by {signal.Signals(-child.returncode).name}" if child.returncode < 0 else ""
    assert child.returncode == 0, f"the child {died or f'exited {child.returncode}'}: {err[-2000:]}"
    words = out.split()
    frames, left = int(words[words.index("frames") + 1]), int(words[words.index("left") + 1])
    assert frames >= 10, f"only {frames} frames streamed: the closes did not happen mid-stream"
    assert left == 0, f"{left} DDS readers or subscribers left on the participant after the cameras closed"
