"""write a journaled scan as a ROS 2 bag (rosbag2 MCAP or SQLite 3) to play with ros2 bag play in RViz or Foxglove

``nbv export-bag DATA_DIR/sessions/ID --out scan.mcap`` (``.db3`` for SQLite 3) writes, per view, the depth image
(``32FC1`` metres, the journal's bytes), the camera info, ``/tf`` (world -> plate -> camera_depth_optical_frame) and
the joint states, then the registered cloud (``PointCloud2``) and the surface (a ``Marker`` triangle list):
workbench/journal/bag.py, docs/bags.md. Needs the ``ros2`` extra (``rosbags``). Used by ``nbv.cli`` as
``add_arguments(parser)`` / ``run(args) -> int``.
"""

from __future__ import annotations

import argparse
from pathlib import Path

from nbv.options import CliError


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("journal", type=Path, metavar="SESSION_DIR", help="a session folder (DATA_DIR/sessions/ID)")
    parser.add_argument(
        "--out",
        type=Path,
        required=True,
        metavar="FILE",
        help="the bag to write: FILE.mcap (MCAP) or FILE.db3 (SQLite 3)",
    )
    parser.add_argument(
        "--distro",
        choices=("humble", "jazzy"),
        default="humble",
        help="the ROS 2 message definitions written into the bag (default %(default)s; both play on later distros)",
    )


def run(args: argparse.Namespace) -> int:
    try:
        import rosbags  # noqa: F401
    except ImportError:
        raise CliError("nbv export-bag needs rosbags: pip install 'nbv-workbench[ros2]'") from None
    from workbench.journal import export_bag

    done = export_bag(args.journal, args.out, args.distro)
    print(
        f"{done.path}: {done.views} views, "
        + (f"{done.move_frames} frames kept during moves, " if done.move_frames else "")
        + f"{done.points} cloud points, {done.triangles} surface triangles, "
        f"{done.bytes / 1e6:.2f} MB in {done.seconds:.1f} s (play: ros2 bag play {done.path})"
    )
    return 0
