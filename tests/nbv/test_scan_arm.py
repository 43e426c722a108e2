"""`nbv scan` with the default arm (the UR5): per-view joints, plate angle, T_base_camera, path length and move
duration in metrics.json; the reported joints give the reported camera pose; no reported configuration is in
collision or outside its limits."""

from __future__ import annotations

import json
import math
from pathlib import Path

import numpy as np
import pytest

from devices.arm.config import ArmConfig
from devices.arm.kinematics import ArmKinematics
from devices.arm.reach import rz_matrix
from devices.builtins import make_builtin
from nbv.cli import main
from planner.types import Pose

SMALL = ["--resolution", "0.02", "--candidates", "60", "--t-min", "2", "--t-max", "6", "--no-reachable"]


def rotation_deg(a: np.ndarray, b: np.ndarray) -> float:
    return math.degrees(math.acos(min(1.0, (np.trace(a.T @ b) - 1) / 2)))


@pytest.fixture(scope="module")
def scan(tmp_path_factory: pytest.TempPathFactory) -> dict:
    out: Path = tmp_path_factory.mktemp("arm") / "scan"
    assert main(["scan", "--model", "mug", "--views", "4", *SMALL, "--out", str(out)]) == 0
    return json.loads((out / "metrics.json").read_text())


def test_every_view_reports_the_arm(scan: dict) -> None:
    assert scan["arm"] == "urdf"
    its = scan["iterations"]
    assert len(its) == 4
    for it in its:
        move = it["move"]
        assert len(move["joints"]) == 6 and all(math.isfinite(v) for v in move["joints"])
        assert -math.pi < move["plate_angle"] <= math.pi
        assert set(move["T_base_camera"]) == {"position", "wxyz"}
        assert move["path_length"] >= 0 and move["move_duration"] >= 0
    for it in its[1:]:  # every move after the first view goes somewhere
        assert it["move"]["path_length"] > 0.01 and it["move"]["move_duration"] > 0.1
        assert it["move"]["path_method"] in ("straight", "rrt_connect")
        assert it["move"]["turn_overlapped"] is False  # the default cell turns, then moves the arm
    assert all(it["plan_cpu_seconds"] > 0 for it in its)  # the plan's CPU time beside its wall time
    parts = sum(
        it["move"]["move_duration"] + it["capture_seconds"] + it["plan_seconds"] + it["move"]["motion_planning_seconds"]
        for it in its
    )
    assert scan["robot_seconds"] == pytest.approx(parts)


def test_forward_kinematics_of_the_reported_joints_gives_the_reported_poses(scan: dict) -> None:
    kin = ArmKinematics(ArmConfig(), plate_radius=0.2, plate_thickness=0.02)
    for it in scan["iterations"]:
        move = it["move"]
        fk = kin.camera_pose(np.array(move["joints"]))
        reported = Pose.from_dict(move["T_base_camera"])
        assert np.linalg.norm(fk.translation - reported.translation) < 1e-3
        assert rotation_deg(fk.rotation, reported.rotation) < 0.1
        table = Pose(rz_matrix(-move["plate_angle"]), np.zeros(3)) @ fk  # the view the planner saw
        pose = Pose.from_dict(it["pose"])
        assert np.linalg.norm(table.translation - pose.translation) < 1e-3
        assert rotation_deg(table.rotation, pose.rotation) < 0.1


def test_no_reported_configuration_collides_or_leaves_its_limits(scan: dict) -> None:
    kin = ArmKinematics(ArmConfig(), plate_radius=0.2, plate_thickness=0.02)
    mug = make_builtin("mug", 0.2)
    lower, upper = mug.bounds  # the true object's box: the arm kept clear of the map's padded box
    kin.set_object_box(lower, upper)
    for it in scan["iterations"]:
        q = np.array(it["move"]["joints"])
        assert kin.model.within_limits(q)
        assert kin.violations(q, it["move"]["plate_angle"]) is None


def test_the_reach_sphere_is_still_there_for_comparison(tmp_path: Path) -> None:
    out = tmp_path / "sphere"
    assert main(["scan", "--model", "l-block", "--views", "2", *SMALL, "--arm", "reach_sphere", "--out", str(out)]) == 0
    doc = json.loads((out / "metrics.json").read_text())
    assert doc["arm"] == "reach_sphere"
    assert all(it["move"]["joints"] is None for it in doc["iterations"])
    assert doc["iterations"][1]["move"]["move_duration"] > 0  # plate turn + camera travel at the nominal speed
