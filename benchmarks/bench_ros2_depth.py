"""How long a depth image takes from the DDS wire to a DepthFrame on the ``ros2`` cell, and what the byte-block
fast path of ``devices/drivers/ros2/messages.py`` saves.

1. (De)serialising one ``sensor_msgs/Image``: our type (``data`` as one byte block) and the same type with cyclonedds'
   generic ``sequence[uint8]`` (one Python int per byte), for a 640x480 16UC1 image (614 kB) and a 1280x720 32FC1
   one (3.7 MB).
2. Over DDS on loopback in one process (a writer and the camera driver's reader on a domain of its own): from
   ``write()`` to the :class:`planner.types.DepthFrame` the camera returns (receive, deserialise, decode, clip).

    PYTHONPATH=$PWD .venv/bin/python benchmarks/bench_ros2_depth.py [--frames 30]
"""

# no "from __future__ import annotations": cyclonedds reads GenericImage's annotations as types

import argparse
import os
import statistics
import time
from dataclasses import dataclass, field

import numpy as np
from cyclonedds.idl import IdlStruct
from cyclonedds.idl.types import sequence, uint8, uint32

from devices.drivers.ros2.camera import depth_of
from devices.drivers.ros2.dds import DdsConfig, Subscription, acquire, release
from devices.drivers.ros2.messages import Header, Image, stamp_of
from planner.types import DepthFrame, Intrinsics, Pose


@dataclass
class GenericImage(IdlStruct, typename="bench::GenericImage_"):
    """``sensor_msgs/Image`` with cyclonedds' generic ``sequence[uint8]`` (the slow path, for comparison)."""

    header: Header = field(default_factory=Header)
    height: uint32 = 0
    width: uint32 = 0
    encoding: str = ""
    is_bigendian: uint8 = 0
    step: uint32 = 0
    data: sequence[uint8] = field(default_factory=list)  # pyright: ignore[reportAssignmentType]


def series(f, n: int) -> list[float]:
    out = []
    for _ in range(n):
        t = time.perf_counter()
        f()
        out.append((time.perf_counter() - t) * 1e3)
    return out


def fmt(ms: list[float]) -> str:
    return f"median {statistics.median(ms):8.2f} ms  min {min(ms):8.2f}  max {max(ms):8.2f}  (n={len(ms)})"


def image(width: int, height: int, encoding: str) -> tuple[Image, bytes]:
    rng = np.random.default_rng(0)
    if encoding == "16UC1":
        pixels = rng.integers(200, 1500, size=(height, width), dtype=np.uint16).astype("<u2")
    else:
        pixels = rng.uniform(0.2, 1.5, size=(height, width)).astype("<f4")
    data = pixels.tobytes()
    msg = Image(
        header=Header(stamp=stamp_of(time.time())),
        height=height,
        width=width,
        encoding=encoding,
        step=len(data) // height,
        data=data,
    )
    return msg, data


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--frames", type=int, default=30)
    ap.add_argument("--repeat", type=int, default=5)
    args = ap.parse_args()
    print(f"load average {os.getloadavg()[0]:.2f} {os.getloadavg()[1]:.2f} {os.getloadavg()[2]:.2f}")
    for width, height, encoding in ((640, 480, "16UC1"), (1280, 720, "32FC1")):
        msg, data = image(width, height, encoding)
        wire = msg.serialize()
        print(f"\n{width}x{height} {encoding}: {len(wire) / 1e6:.2f} MB on the wire")
        print(f"  byte block  serialise   {fmt(series(msg.serialize, args.repeat * 4))}")
        print(f"  byte block  deserialise {fmt(series(lambda wire=wire: Image.deserialize(wire), args.repeat * 4))}")
        generic = GenericImage(msg.header, height, width, encoding, 0, msg.step, list(data))  # pyright: ignore[reportArgumentType]
        assert generic.serialize() == wire  # the same bytes
        print(f"  generic     serialise   {fmt(series(generic.serialize, args.repeat))}")
        print(f"  generic     deserialise {fmt(series(lambda wire=wire: GenericImage.deserialize(wire), args.repeat))}")

    node = acquire(DdsConfig(domain_id=1 + os.getpid() % 200, interface="lo", peers=("127.0.0.1",)))
    try:
        sub = Subscription(node, "/camera/camera/depth/image_rect_raw", Image)
        writer = node.sensor_writer("/camera/camera/depth/image_rect_raw", Image)
        time.sleep(0.5)
        k = Intrinsics(640, 480, 610.0, 610.0, 319.5, 239.5)
        msg, _ = image(640, 480, "16UC1")
        latencies = []
        for _ in range(args.frames):
            seen = sub.count
            t = time.perf_counter()
            writer.write(msg)
            got = sub.wait(lambda m, seen=seen: sub.count > seen, 2.0)
            assert got is not None, "no image came back over loopback"
            depth = depth_of(got)
            depth[(depth < 0.1) | (depth > 1.5)] = 0.0
            DepthFrame(depth, Pose.identity(), k)
            latencies.append((time.perf_counter() - t) * 1e3)
            time.sleep(0.03)
        print(f"\nDDS loopback, 640x480 16UC1, write() -> DepthFrame: {fmt(latencies)}")
    finally:
        release(node)


if __name__ == "__main__":
    main()
