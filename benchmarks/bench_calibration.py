"""Calibration of a simulated cell: how well the routine recovers the hand-eye transform and the turntable axis.

Run: ``.venv/bin/python benchmarks/bench_calibration.py [--seeds 10] [--calibration poor] [--sensor realsense-d435]``.

Per seed (one random draw of the cell's errors at ``--calibration``): the errors of the recovered hand-eye
transform (mm, degrees) and axis (mm at the plate top, degrees), the nominal errors before calibration, the
reported one-sigma uncertainty, captures and seconds; then the median and max of each. Goal: hand-eye
and axis within 1 mm and 0.2 degrees at 'poor'. Then how honest the reported uncertainty is: per quantity, in how
many draws the true error lies within the reported 95 % bound (``*_bound95_*``: ~95 % of the draws should), and
the RMS of error / one-sigma (1 for an exact sigma).
"""

from __future__ import annotations

import argparse
import json
import statistics

from devices.calibration import calibrate_sim

KEYS = ("hand_eye_error_mm", "hand_eye_error_deg", "axis_error_mm", "axis_error_deg", "captures", "seconds")


def main() -> None:
    parser = argparse.ArgumentParser(description=(__doc__ or "").splitlines()[0])
    parser.add_argument("--seeds", type=int, default=10)
    parser.add_argument("--calibration", default="poor")
    parser.add_argument("--sensor", default="realsense-d435")
    parser.add_argument("--json", action="store_true", help="also print every run's JSON")
    args = parser.parse_args()
    rows = []
    print(f"calibration={args.calibration} sensor={args.sensor}")
    header = "seed  he_mm  he_deg  ax_mm  ax_deg | before: he_mm he_deg ax_mm ax_deg | std: he_mm he_deg ax_mm ax_deg"
    print(header + " | captures seconds")
    for seed in range(args.seeds):
        out = calibrate_sim(args.sensor, args.calibration, seed)
        rows.append(out)
        b, r = out["nominal_error"], out["recovered"]
        print(
            f"{seed:4d} {out['hand_eye_error_mm']:6.3f} {out['hand_eye_error_deg']:7.3f} {out['axis_error_mm']:6.3f}"
            f" {out['axis_error_deg']:7.3f} |   {b['hand_eye_mm']:6.2f} {b['hand_eye_deg']:6.2f} {b['axis_mm']:5.2f}"
            f" {b['axis_deg']:6.2f} |  {r['hand_eye_std_mm']:5.3f} {r['hand_eye_std_deg']:6.3f}"
            f" {r['axis_std_mm']:5.3f} {r['axis_std_deg']:6.3f} | {out['captures']:8d} {out['seconds']:7.1f}",
            flush=True,
        )
        if args.json:
            print(json.dumps(out))
    print("summary (median / max):")
    for key in KEYS:
        values = [float(row[key]) for row in rows]
        print(f"  {key:20s} {statistics.median(values):8.3f} / {max(values):8.3f}")
    ok = all(
        row["hand_eye_error_mm"] <= 1
        and row["hand_eye_error_deg"] <= 0.2
        and row["axis_error_mm"] <= 1
        and row["axis_error_deg"] <= 0.2
        for row in rows
    )
    print(f"goal (every seed within 1 mm and 0.2 deg): {'met' if ok else 'NOT met'}")
    print("uncertainty (draws with the error within the reported 95 % bound; rms of error / one sigma):")
    for quantity in ("hand_eye_mm", "hand_eye_deg", "axis_mm", "axis_deg"):
        what, unit = quantity.rsplit("_", 1)
        inside = sum(row[f"{what}_error_{unit}"] <= row["recovered"][f"{what}_bound95_{unit}"] for row in rows)
        ratio = [row[f"{what}_error_{unit}"] / row["recovered"][f"{what}_std_{unit}"] for row in rows]
        rms = statistics.fmean(r * r for r in ratio) ** 0.5
        print(f"  {quantity:14s} within the 95 % bound in {inside} of {len(rows)} draws; error / sigma rms {rms:.2f}")


if __name__ == "__main__":
    main()
