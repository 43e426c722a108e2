"""nbv calibrate: commission a cell (hand-eye transform and turntable axis from a sphere target on the plate).

``nbv calibrate --cell cell.toml [--dry-run] [--yes] [--write]``: the poses are listed (a dry run rehearses them on
the arm model: reachability, move time, spheres in view; nothing is opened or moved), approved (``--yes`` or a
typed ``y``), visited; prints the residual per capture, the estimate and its uncertainty; ``--write`` writes the
result into the cell file (the old file kept as ``<name>.<time>.bak``).
``nbv calibrate --sim --calibration poor --seed N [--sensor realsense-d435] [--json]``: the same on a simulated cell
whose errors are drawn from the seed, compared with the truth (``--json``: one JSON object).
"""

from __future__ import annotations

import argparse
import json
import math
import sys
from pathlib import Path
from typing import Any

from devices.config import ARM_CHOICES_HELP
from nbv.options import CliError, arm_name


def add_arguments(p: argparse.ArgumentParser) -> None:
    source = p.add_mutually_exclusive_group(required=True)
    source.add_argument("--cell", type=Path, help="the cell file (TOML with a [devices] table) of a real cell")
    source.add_argument("--sim", action="store_true", help="a simulated cell with drawn calibration errors")
    p.add_argument("--dry-run", action="store_true", help="list and rehearse the poses; move nothing")
    p.add_argument("--yes", action="store_true", help="approve the pose list without asking (real cell)")
    p.add_argument("--write", action="store_true", help="write the result into the cell file (a backup is kept)")
    p.add_argument("--calibration", default="poor", help="--sim: the calibration error model (default poor)")
    p.add_argument("--sensor", default="realsense-d435", help="--sim: the sensor model (default realsense-d435)")
    p.add_argument("--seed", type=int, default=0, help="--sim: seeds the drawn errors and the noise (default 0)")
    p.add_argument("--angle-sigma-deg", type=float, default=0.1, help="plate angle error per move, deg (0: exact)")
    p.add_argument("--json", action="store_true", help="print one JSON object")
    p.add_argument(
        "--arm",
        type=arm_name,
        default=None,
        help=f"the arm model: {ARM_CHOICES_HELP} (default ur5; a real cell's mount and hand-eye come from its file)",
    )
    p.add_argument(
        "--plate-angles", default=None, help="plate angles of the poses, degrees, comma-separated (default 6: 0,60,...)"
    )


def _cell(args: argparse.Namespace) -> Any:
    """The default cell with ``--arm`` (a ``devices.config.CellConfig``)."""
    from devices.config import CellConfig, cell_with_arm

    return cell_with_arm(CellConfig(), getattr(args, "arm", None))


def _plate_angles(text: str | None) -> dict[str, Any]:
    """Calibration keyword arguments for --plate-angles."""
    if text is None:
        return {}
    try:
        angles = tuple(float(v) for v in text.split(","))
    except ValueError:
        raise CliError(f"--plate-angles: comma-separated degrees, got {text!r}") from None
    return {"plate_angles_deg": angles}


def _pose_line(i: int, label: str, text: str) -> str:
    return f"{i + 1:3d} {label:24s} {text}"


def _progress(quiet: bool) -> Any:
    def report(i: int, pose: Any, capture: Any) -> None:
        if quiet:
            return
        if capture is None:
            print(_pose_line(i, pose.label, "skipped"), flush=True)
            return
        rms = ", ".join("-" if math.isnan(r) else f"{r * 1000:.2f}" for r in capture.fit_rms)
        print(_pose_line(i, pose.label, f"{int(capture.seen.sum())} spheres, fit rms mm [{rms}]"), flush=True)

    return report


def _print_result(data: dict[str, Any]) -> None:
    """The estimate as :meth:`CalibrationResult.to_json` gives it: residual per capture, values, uncertainty."""
    print("residual per capture (rms of the sphere centres, mm):")
    for label, r in data["residuals_mm"].items():
        print(f"    {label:24s} {r:6.3f}")
    t, rpy = data["hand_eye_translation"], data["hand_eye_rotation_deg"]
    print(
        f"hand-eye T_flange_camera: translation [{', '.join(f'{v:.5f}' for v in t)}] m, "
        f"rotation_deg [{', '.join(f'{v:.4f}' for v in rpy)}]  "
        f"(+-{data['hand_eye_std_mm']:.3f} mm, +-{data['hand_eye_std_deg']:.4f} deg)"
    )
    p, d = data["axis_point"], data["axis_direction"]
    print(
        f"turntable axis: through [{p[0] * 1000:.3f}, {p[1] * 1000:.3f}] mm at the plate top, direction "
        f"[{', '.join(f'{v:.5f}' for v in d)}], tilt {data['axis_tilt_deg']:.3f} deg  "
        f"(+-{data['axis_std_mm']:.3f} mm, +-{data['axis_std_deg']:.4f} deg)"
    )
    print(f"rms {data['rms_mm']:.3f} mm over {len(data['residuals_mm'])} captures")


def _dry_run(routine: Any) -> int:
    """Rehearse every pose on the given (simulated) cell: plan, move, look."""
    from devices.protocols import UnreachableError

    for i, pose in enumerate(routine.poses):
        try:
            motion = routine.preview(i)
        except UnreachableError as exc:
            print(_pose_line(i, pose.label, f"UNREACHABLE ({exc})"))
            routine.skipped.append((pose.label, str(exc)))
            continue
        capture = routine.capture(i)
        seen = 0 if capture is None else int(capture.seen.sum())
        print(
            _pose_line(
                i,
                pose.label,
                f"plate {math.degrees(motion.angle):7.1f} deg, move {motion.duration:5.1f} s, "
                f"{seen} of {routine.target.count} spheres in view",
            )
        )
    reachable = len(routine.poses) - len(routine.skipped)
    print(f"dry run: {reachable} of {len(routine.poses)} poses reachable; nothing was moved")
    return 0


def run(args: argparse.Namespace) -> int:
    from devices.calibration import Calibration, CalibrationError, calibrate_sim, calibration_sim_cell

    try:
        if args.sim:
            if args.write:
                raise CliError("--write needs --cell (the simulated cell has no file)")
            if args.dry_run:
                cell = calibration_sim_cell(args.sensor, args.calibration, args.seed, cell_config=_cell(args))
                return _dry_run(Calibration(cell, **_plate_angles(args.plate_angles)))
            out = calibrate_sim(
                args.sensor,
                args.calibration,
                args.seed,
                args.angle_sigma_deg,
                progress=_progress(args.json),
                cell_config=_cell(args),
                **_plate_angles(args.plate_angles),
            )
            if args.json:
                print(json.dumps(out))
                return 0
            _print_result(out["recovered"])
            before = out["nominal_error"]
            print("against the truth (the nominal values' error in brackets):")
            for key, nominal in (("hand_eye_error_mm", "hand_eye_mm"), ("hand_eye_error_deg", "hand_eye_deg")):
                print(f"    {key:20s} {out[key]:8.4f}   ({before[nominal]:.4f})")
            for key, nominal in (("axis_error_mm", "axis_mm"), ("axis_error_deg", "axis_deg")):
                print(f"    {key:20s} {out[key]:8.4f}   ({before[nominal]:.4f})")
            return 0
        return _run_cell(args, Calibration)
    except CalibrationError as exc:
        raise CliError(str(exc)) from None


def _run_cell(args: argparse.Namespace, Calibration: Any) -> int:
    from devices.calibration import DEFAULT_TARGET, write_calibration
    from devices.cellfile import load_cell_file
    from devices.config import CameraConfig
    from devices.hwcell import arm_cell_config, hardware_cell
    from devices.rig import open_rig
    from devices.sim import make_sim_cell

    cellfile = load_cell_file(args.cell)
    if args.dry_run:
        rehearsal = make_sim_cell(DEFAULT_TARGET.mesh(), CameraConfig(), arm_cell_config(cellfile, _cell(args)))
        return _dry_run(Calibration(rehearsal, **_plate_angles(args.plate_angles)))
    with open_rig(cellfile) as rig:
        routine = Calibration(hardware_cell(rig, _cell(args)), **_plate_angles(args.plate_angles))
        print(
            f"{len(routine.poses)} poses (the target: {DEFAULT_TARGET.count} spheres of "
            f"{DEFAULT_TARGET.radius * 2000:.0f} mm on the plate):"
        )
        for i, pose in enumerate(routine.poses):
            print(_pose_line(i, pose.label, f"plate {math.degrees(pose.plate_angle):7.1f} deg"))
        if not args.yes:
            answer = input("move the arm and the plate through these poses? [y/N] ").strip().lower()
            if answer not in ("y", "yes"):
                print("not approved: nothing moved")
                return 1
        result = routine.run(_progress(args.json), args.angle_sigma_deg)
    if args.json:
        print(json.dumps(result.to_json()))
    else:
        for label, reason in routine.skipped:
            print(f"skipped {label}: {reason}", file=sys.stderr)
        _print_result(result.to_json())
    if args.write:
        backup = write_calibration(args.cell, result)
        print(f"wrote {args.cell} (the old file kept as {backup})")
    return 0
