"""Every arm preset works out of the box: it loads from the installed example-robot-data (package:// meshes, SRDF,
locked joints), scans in the simulated cell (a 5-view scan: every view taken or refused with its reason, the locked
joints never move), and ``nbv arms check`` reports the share of the hemisphere it reaches."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from devices.arm.config import ArmConfig
from devices.arm.model import load_arm
from devices.arm.mount import hemisphere, object_box, reach_report
from devices.arm.presets import PRESETS
from devices.config import CellConfig, cell_with_arm
from nbv.cli import main
from planner import PlannerConfig
from workbench.evaluation.simulate import SimScan, simulate

SMALL = PlannerConfig().replace(
    voxel={"resolution": 0.015}, candidates={"count": 24, "parallels": 3}, termination={"max_views": 5}
)


@pytest.fixture(scope="module", params=sorted(PRESETS))
def scan(request: pytest.FixtureRequest) -> SimScan:
    return simulate("mug", SMALL, size=0.15, reachable=False, arm=request.param)


@pytest.mark.slow
def test_a_preset_scans_five_views_each_taken_or_refused_with_a_reason(scan: SimScan) -> None:
    result = scan.result
    assert len(result.records) == 5 and result.terminated == "max_views"
    for refused in result.refused_moves:  # a refused view carries the cell's reason
        assert str(refused.get("message", "")).strip() != ""
    coverage = [r.coverage for r in result.records]
    assert all(c is not None for c in coverage) and coverage[-1] > 0.5
    assert result.robot_seconds > 0


@pytest.mark.slow
def test_the_locked_joints_never_move(scan: SimScan) -> None:
    """The locked joints are not among the arm's: every configuration the arm reports has the preset's joint count,
    and the model keeps each locked joint at its value."""
    preset = PRESETS[scan.cell.config.arm.urdf]
    kinematics = scan.cell.reach.kinematics
    names = kinematics.joint_names
    assert len(names) == preset.dof
    assert not {j for j, _ in preset.locked_joints} & set(names)
    assert kinematics.model.locked == tuple(preset.locked_joints)
    q = scan.cell.reach.joint_positions()
    assert q is not None and q.shape == (preset.dof,)


def test_a_preset_resolves_its_meshes_and_srdf_without_configuration() -> None:
    model = load_arm(ArmConfig(urdf="panda"), (-0.6, 0.0, 0.0))
    assert model.srdf_path is not None and model.srdf_path.name == "panda.srdf"
    assert model.nq == 7 and model.geometry.ngeoms > 8
    assert model.locked == (("panda_finger_joint1", 0.02), ("panda_finger_joint2", 0.02))


def test_fields_left_at_their_defaults_come_from_the_preset() -> None:
    cfg = ArmConfig(urdf="xarm7")
    assert cfg.flange == "link_eef" and cfg.mount == PRESETS["xarm7"].base and len(cfg.home) == 7
    own = ArmConfig(urdf="xarm7", base=(-0.7, 0.1, 0.0), flange_frame="link7")
    assert own.mount == (-0.7, 0.1, 0.0) and own.flange == "link7"
    assert ArmConfig(urdf="robot.urdf").flange == "tool0" and ArmConfig(urdf="robot.urdf").home == ()


def test_a_bad_locked_joint_names_the_field() -> None:
    with pytest.raises(ValueError, match=r"^arm\.locked_joints: no joint 'nope'"):
        load_arm(ArmConfig(urdf="ur5", locked_joints=("nope",)), (-0.85, 0.0, 0.0))
    with pytest.raises(ValueError, match=r"^arm\.locked_positions: need one value per locked joint"):
        ArmConfig(locked_joints=("a", "b"), locked_positions=(0.0,))


def test_the_arm_name_picks_the_cell() -> None:
    assert cell_with_arm(CellConfig(), "panda").arm.urdf == "panda"
    assert cell_with_arm(CellConfig(), "reach_sphere").kinematics == "reach_sphere"
    assert cell_with_arm(CellConfig(), "urdf").arm.urdf == "ur5"
    with pytest.raises(ValueError, match=r"^--arm: 'kuka' is no preset"):
        cell_with_arm(CellConfig(), "kuka")


def test_arms_check_json_reports_the_share_it_counted(capsys: pytest.CaptureFixture[str]) -> None:
    """``nbv arms check ur5 --base ... --json``: the JSON's shape, and its share equals a direct count of the
    reachable views of the same small hemisphere."""
    assert main(["arms", "check", "ur5", "--base=-0.85,0,0", "--candidates", "40", "--json"]) == 0
    doc = json.loads(capsys.readouterr().out)
    assert set(doc) >= {"reachable_share", "base", "candidates", "per_parallel", "reasons", "object_size"}
    assert doc["base"] == [-0.85, 0.0, 0.0] and doc["candidates"] == 40
    from devices.arm.kinematics import ArmKinematics

    cell = CellConfig()
    k = ArmKinematics(ArmConfig(), cell.plate_radius, cell.plate_thickness)
    box = object_box(0.2)
    k.set_object_box(box.lower, box.upper)
    views = hemisphere(0.2, count=40)
    direct = sum(k.reachability(c.T_world_camera, k.home, 0.0)[0] for c in views)
    assert doc["reachable_share"] == pytest.approx(direct / 40)
    assert 0.0 < doc["reachable_share"] < 1.0  # the UR5 at its default mount misses the top parallels
    assert sum(p["views"] for p in doc["per_parallel"]) == 40
    assert sum(doc["reasons"].values()) == 40 - direct


def test_arms_lists_the_presets(capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["arms"]) == 0
    out = capsys.readouterr().out
    for name in PRESETS:
        assert name in out


def test_a_reach_report_of_a_seven_joint_preset_reaches_most_of_the_hemisphere() -> None:
    report = reach_report(ArmConfig(urdf="panda"), 0.2, count=40)
    assert report.reachable_share >= 0.9
    assert report.base == PRESETS["panda"].base


@pytest.mark.slow
def test_scan_takes_the_arm_from_a_config_file(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    """``nbv scan --config`` with a [devices.cell.arm] section (the layout of nbv serve) scans with that arm."""
    config = tmp_path / "lab.toml"
    config.write_text(
        '[voxel]\nresolution = 0.015\n[candidates]\ncount = 30\nparallels = 3\n[devices.cell.arm]\nurdf = "ur10"\n'
    )
    out = tmp_path / "out"
    code = main(
        ["scan", "--model", "l-block", "--config", str(config), "--views", "2", "--no-reachable", "--out", str(out)]
    )
    assert code == 0, capsys.readouterr().err
    doc = json.loads((out / "metrics.json").read_text())
    assert doc["arm_model"] == "ur10" and len(doc["iterations"]) >= 1
    assert np.isfinite(doc["robot_seconds"])
