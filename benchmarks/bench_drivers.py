"""Time the hardware drivers' own overhead, without hardware: a RealSense capture from a recording, a GRBL
status round trip and a Modbus RTU read over a pseudo terminal.

Run: ``PYTHONPATH=. .venv/bin/python benchmarks/bench_drivers.py [--repeat 20]``. Prints the median and
the maximum wall time per call. The RealSense numbers are the driver's cost per capture (decode, filters,
averaging) at 640 x 480, not a camera's frame interval (a live D435 delivers a frame every 33 ms at 30 fps);
the serial numbers are the protocol round trip against the fakes of ``tests/devices/drivers`` (a real
USB serial link adds its latency, about 1 ms per transfer).
"""

from __future__ import annotations

import argparse
import statistics
import tempfile
import time
from collections.abc import Callable
from pathlib import Path

from devices.config import CameraConfig
from devices.drivers.grbl import GrblConfig, GrblTurntable
from devices.drivers.modbus import ModbusTurntable, ModbusTurntableConfig
from devices.drivers.realsense import RealSenseCamera, RealSenseConfig
from devices.drivers.rsrecord import write_depth_recording
from tests.devices.drivers.fake_grbl import FakeGrbl
from tests.devices.drivers.fake_modbus import FakeModbusDrive
from tests.devices.drivers.rsfixtures import rendered_views


def timed(fn: Callable[[], object], repeat: int) -> list[float]:
    times = []
    for _ in range(repeat):
        t0 = time.perf_counter()
        fn()
        times.append(time.perf_counter() - t0)
    return times


def report(name: str, times: list[float]) -> None:
    print(f"{name:48s} median {1000 * statistics.median(times):8.2f} ms   max {1000 * max(times):8.2f} ms")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--repeat", type=int, default=20)
    args = parser.parse_args()
    n = args.repeat
    camera = CameraConfig(min_depth=0.05, max_depth=3.0)  # 640 x 480
    with tempfile.TemporaryDirectory() as tmp:
        depths, k = rendered_views(1, camera)
        for average, filters in ((1, ()), (3, ()), (1, ("spatial", "temporal", "hole_filling"))):
            path = write_depth_recording(Path(tmp) / f"bench{average}{len(filters)}.db3", depths * (n * average), k)
            config = RealSenseConfig(playback=str(path), average=average, filters=filters, min_depth=0.05)
            with RealSenseCamera(config) as cam:
                label = f"RealSense capture 640x480, average {average}" + (
                    f", {len(filters)} filters" if filters else ""
                )
                report(label, timed(cam.capture, n))
    with FakeGrbl() as grbl, GrblTurntable(GrblConfig(port=grbl.port)) as table:
        report("GRBL status round trip (?)", timed(lambda: table.angle, n))
    with FakeModbusDrive() as drive, ModbusTurntable(ModbusTurntableConfig(port=drive.port, baudrate=115200)) as mb:
        report("Modbus RTU read position (fc 3, 2 registers)", timed(lambda: mb.angle, n))


if __name__ == "__main__":
    main()
