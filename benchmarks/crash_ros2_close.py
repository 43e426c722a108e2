"""Close a streaming ROS 2 camera mid-stream, over and over: does the process survive?

A publisher process sends 640x480 16UC1 depth images and their CameraInfo at 30 Hz over loopback (a DDS domain
of its own, unicast discovery to 127.0.0.1); each trial is a fresh consumer process that opens a
:class:`devices.drivers.ros2.camera.Ros2Camera`, streams (a thread of ours drains the stream and decodes frames),
and closes the camera while images keep arriving, ``--closes`` times. A trial that dies by a signal is a crash.

    PYTHONPATH=$PWD .venv/bin/python benchmarks/crash_ros2_close.py --trials 6 --closes 20

Prints one line per trial (exit status, seconds, frames decoded, DDS entities other than topics left on the
participant after the closes) and the crash count. ``--collect`` runs the garbage collector after each close
(without it the crash waits for the collector's own time).
"""

from __future__ import annotations

import argparse
import gc
import os
import signal
import subprocess
import sys
import threading
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
DEPTH_TOPIC = "/camera/camera/depth/image_rect_raw"
INFO_TOPIC = "/camera/camera/depth/camera_info"


def publish(domain: int, width: int, height: int, rate_hz: float) -> int:
    """Publish depth images and camera info on ``domain`` until stdin closes: a plain cyclonedds participant with
    our ROS 2 message types, the module loaded by path (importing ``devices`` would cost seconds)."""
    import importlib.util

    import numpy as np
    from cyclonedds.core import Policy
    from cyclonedds.domain import Domain, DomainParticipant
    from cyclonedds.pub import DataWriter
    from cyclonedds.qos import Qos
    from cyclonedds.topic import Topic

    spec = importlib.util.spec_from_file_location("ros2_messages", ROOT / "devices/drivers/ros2/messages.py")
    assert spec is not None and spec.loader is not None
    m = importlib.util.module_from_spec(spec)
    sys.modules["ros2_messages"] = m
    spec.loader.exec_module(m)
    CameraInfo, Header, Image, RegionOfInterest, stamp_of = (
        m.CameraInfo,
        m.Header,
        m.Image,
        m.RegionOfInterest,
        m.stamp_of,
    )
    xml = (
        '<CycloneDDS><Domain><General><Interfaces><NetworkInterface name="lo"/></Interfaces>'
        "<AllowMulticast>false</AllowMulticast></General><Discovery><ParticipantIndex>auto</ParticipantIndex>"
        '<MaxAutoParticipantIndex>64</MaxAutoParticipantIndex><Peers><Peer address="127.0.0.1"/></Peers>'
        "</Discovery></Domain></CycloneDDS>"
    )  # DdsConfig(domain, "lo", ("127.0.0.1",)).xml()
    _domain = Domain(domain, xml)
    participant = DomainParticipant(domain)
    qos = Qos(Policy.Reliability.BestEffort, Policy.Durability.Volatile, Policy.History.KeepLast(5))  # a sensor's
    image_writer = DataWriter(participant, Topic(participant, "rt" + DEPTH_TOPIC, Image), qos=qos)
    info_writer = DataWriter(participant, Topic(participant, "rt" + INFO_TOPIC, CameraInfo), qos=qos)
    stop = threading.Event()
    fx = 0.8 * width
    mm = np.full((height, width), 800, dtype="<u2")

    def loop() -> None:
        while not stop.is_set():
            began = time.monotonic()
            header = Header(stamp=stamp_of(time.time()), frame_id="camera_depth_optical_frame")
            info_writer.write(
                CameraInfo(
                    header=header,
                    height=height,
                    width=width,
                    distortion_model="plumb_bob",
                    d=[0.0] * 5,
                    k=[fx, 0.0, (width - 1) / 2, 0.0, fx, (height - 1) / 2, 0.0, 0.0, 1.0],
                    r=[1.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 1.0],
                    p=[fx, 0.0, (width - 1) / 2, 0.0, 0.0, fx, (height - 1) / 2, 0.0, 0.0, 0.0, 1.0, 0.0],
                    roi=RegionOfInterest(),
                )
            )
            image_writer.write(
                Image(header=header, height=height, width=width, encoding="16UC1", step=width * 2, data=mm)
            )
            time.sleep(max(0.0, 1.0 / rate_hz - (time.monotonic() - began)))

    thread = threading.Thread(target=loop, daemon=True)
    thread.start()
    print("ready", flush=True)
    sys.stdin.read()
    stop.set()
    thread.join()
    return 0


def consume(domain: int, closes: int, hold_s: float, collect: bool) -> int:
    """Open, stream from and close a camera ``closes`` times (a draining thread running at each close)."""
    from devices.drivers.ros2.camera import Ros2Camera, Ros2CameraConfig
    from devices.drivers.ros2.dds import acquire, release
    from devices.movestream import FrameQueue

    config = Ros2CameraConfig(domain_id=domain, interface="lo", peers=("127.0.0.1",), timeout_s=3.0)
    # the cell's other ros2 devices (arm, turntable) share the participant: it outlives each camera
    others = acquire(config.dds)
    gc.freeze()  # the imports' objects are never garbage: a collection then looks at the cameras' objects alone
    frames_seen = 0
    began = time.monotonic()
    for _ in range(closes):
        camera = Ros2Camera(config)
        frames = camera.stream()
        stop = threading.Event()

        def drain(frames: FrameQueue = frames, stop: threading.Event = stop) -> None:
            nonlocal frames_seen
            while not stop.is_set():
                frame = frames.get(0.01)
                if frame is not None:
                    frame.decode()
                    frames_seen += 1

        thread = threading.Thread(target=drain, daemon=True)
        thread.start()
        time.sleep(hold_s)
        camera.close()  # mid-stream: images keep arriving, our drain thread still runs
        del camera
        if collect:
            gc.collect()
        stop.set()
        thread.join()
        frames.close()
    from cyclonedds.topic import Topic

    left = [e for e in others.participant.children if not isinstance(e, Topic)]
    release(others)
    print(f"frames {frames_seen} left {len(left)} loop {time.monotonic() - began:.2f} s", flush=True)
    return 0


def main() -> int:
    parser = argparse.ArgumentParser(description=(__doc__ or "").split("\n\n")[0])
    parser.add_argument("--trials", type=int, default=6, help="consumer processes")
    parser.add_argument("--closes", type=int, default=20, help="camera closes per consumer")
    parser.add_argument("--hold", type=float, default=0.1, help="seconds each camera streams before it closes")
    parser.add_argument("--size", default="640x480", help="depth image size")
    parser.add_argument("--rate", type=float, default=30.0, help="images per second")
    parser.add_argument("--collect", action="store_true", help="gc.collect() after each close (else the GC's own time)")
    parser.add_argument("--role", default="", help=argparse.SUPPRESS)
    parser.add_argument("--domain", type=int, default=0, help=argparse.SUPPRESS)
    args = parser.parse_args()
    if args.role == "publish":
        w, h = (int(v) for v in args.size.split("x"))
        return publish(args.domain, w, h, args.rate)
    if args.role == "consume":
        return consume(args.domain, args.closes, args.hold, args.collect)
    domain = 1 + (os.getpid() * 7) % 200
    env = {**os.environ, "PYTHONPATH": str(ROOT), "OMP_NUM_THREADS": "1"}
    me = [sys.executable, __file__, "--domain", str(domain), "--size", args.size, "--rate", str(args.rate)]
    publisher = subprocess.Popen([*me, "--role", "publish"], env=env, stdin=subprocess.PIPE, stdout=subprocess.PIPE)
    assert publisher.stdout is not None and publisher.stdin is not None
    assert publisher.stdout.readline().strip() == b"ready"
    crashes = 0
    try:
        for trial in range(args.trials):
            began = time.monotonic()
            run = subprocess.run(
                [*me, "--role", "consume", "--closes", str(args.closes), "--hold", str(args.hold)]
                + (["--collect"] if args.collect else []),
                env=env,
                capture_output=True,
                text=True,
                timeout=120,
            )
            status = f"exit {run.returncode}"
            if run.returncode < 0:
                crashes += 1
                status = f"killed by {signal.Signals(-run.returncode).name}"
            print(f"trial {trial}: {status}, {time.monotonic() - began:.1f} s {run.stdout.strip()}", flush=True)
            if run.returncode != 0 and run.stderr.strip():
                print("  " + run.stderr.strip().splitlines()[-1])
    finally:
        publisher.stdin.close()
        publisher.wait(timeout=10)
    print(f"crashes: {crashes}/{args.trials} trials of {args.closes} closes each")
    return 0


if __name__ == "__main__":
    sys.exit(main())
