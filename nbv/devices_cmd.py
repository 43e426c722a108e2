"""nbv devices check: connect to each device of a cell file, read its state, one line per device.

Exit 0 when every device answered, 1 when any failed; a bad cell file is one error line and exit 2. A cell with
``ros2`` devices also gets one line per topic the cell file names (its type, rate, and what is missing; a missing
topic is a failure too).
"""

from __future__ import annotations

import argparse
from pathlib import Path


def add_arguments(p: argparse.ArgumentParser) -> None:
    sub = p.add_subparsers(dest="devices_command", required=True)
    check = sub.add_parser("check", help="connect to each device of the cell file and read its state")
    check.add_argument(
        "--config",
        "--cell",
        dest="config",
        type=Path,
        required=True,
        help="the cell file (TOML with a [devices] table)",
    )


def run(args: argparse.Namespace) -> int:
    from devices.cellfile import load_cell_file
    from devices.rig import check_devices

    cell = load_cell_file(args.config)
    if not cell.devices():
        raise ValueError(f"{args.config}: no devices configured ([devices.camera], [devices.arm], [devices.turntable])")
    results = check_devices(cell)
    for result in results:
        print(result.line(), flush=True)
    failed = sum(not r.ok for r in results)
    print(f"{len(results) - failed} of {len(results)} devices ok" + (f"; {failed} failed" if failed else ""))
    missing = 0
    if any(spec.driver == "ros2" for spec in cell.devices()):
        from devices.drivers.ros2.check import topic_report

        topics = topic_report(cell)
        missing = sum(not t.ok for t in topics)
        print(f"ROS 2 topics (DDS domain {next(s for s in cell.devices() if s.driver == 'ros2').config.domain_id}):")
        for topic in topics:
            print(topic.line())
        print(f"{len(topics) - missing} of {len(topics)} topics ok" + (f"; {missing} missing" if missing else ""))
    return 1 if failed or missing else 0
