"""One name per setting: every field of the configuration dataclasses is settable from the command line, from a
TOML file and (the planner's) over REST, under the same dotted name, and docs/configuration.md is the page
generated from them.

Each test walks the dataclasses, gives every field a valid value other than its default (:func:`other_value`),
sets them all through one channel and asserts that each one landed. Fields that a channel cannot set are in an
explicit exclusion table with the reason.
"""

from __future__ import annotations

import argparse
import dataclasses
import typing
from pathlib import Path
from typing import Any, Literal

import pytest
from fastapi.testclient import TestClient

from app.main import create_app
from app.settings import AppSettings, load_settings
from devices.arm.config import DEFAULT_T_FLANGE_CAMERA
from devices.config import DeviceConfig
from devices.faults import FaultConfig
from nbv import config_doc, serve
from nbv.cli import build_parser, main
from nbv.flags import ConfigField, config_fields, first_sentence, render_value
from nbv.options import PLANNER_ALIASES, planner_config_from_args
from planner.config import REMOVED, PlannerConfig

REPO = Path(__file__).resolve().parents[2]

OTHER: dict[str, Any] = {
    # values the generic rule cannot find: strings, empty lists, a matrix, and values whose neighbours
    # cross a cross-field rule
    "server.host": "localhost",
    "server.viser_host": "localhost",
    "server.token": "a-long-enough-token",
    "server.cors_origins": ("https://lab.example",),
    "server.allowed_hosts": ("scanner.local",),
    "server.cell": "cell.toml",
    "server.models_dir": Path("other-models"),
    "server.data_dir": Path("other-data"),
    "devices.model": "mug",
    "devices.camera.sensor": "realsense-d435",
    "devices.camera.calibration": "typical",
    "devices.cell.arm.urdf": "robot.urdf",
    "devices.cell.arm.srdf": "robot.srdf",
    "devices.cell.arm.flange_frame": "tool1",
    "devices.cell.arm.package_dirs": ("meshes",),
    "devices.cell.arm.base": (-0.7, 0.1, 0.02),
    "devices.cell.arm.home_deg": (0.0, -80.0, 80.0, -90.0, -90.0, 0.0),
    "devices.cell.arm.locked_joints": ("finger_joint",),
    "devices.cell.arm.locked_positions": (0.01,),
    "devices.cell.arm.joint_lower_deg": (-350.0, -350.0, -170.0, -350.0, -350.0, -350.0),
    "devices.cell.arm.joint_upper_deg": (350.0, 350.0, 170.0, 350.0, 350.0, 350.0),
    "devices.cell.arm.T_flange_camera": tuple(
        tuple(0.06 if (i, j) == (2, 3) else v for j, v in enumerate(row))
        for i, row in enumerate(DEFAULT_T_FLANGE_CAMERA)
    ),
    "faults.schedule": ({"kind": "capture_failure", "at": 3},),
}


def other_value(f: ConfigField) -> Any:
    """A valid value of ``f`` other than its default."""
    if f.name in OTHER:
        return OTHER[f.name]
    d, annotation = f.default, f.annotation
    if isinstance(d, bool):
        return not d
    if typing.get_origin(annotation) is Literal:
        return next(a for a in typing.get_args(annotation) if a != d)
    if isinstance(d, int):
        return d + 1
    if isinstance(d, float):
        return 0.001 if d == 0 else round(d * 0.9, 6)
    if isinstance(d, tuple) and d and all(isinstance(v, float) for v in d):
        return tuple(round(v + 1.0, 6) for v in d)
    raise AssertionError(f"{f.name}: add a value to OTHER")


def expected(f: ConfigField, prefix: int = 0) -> Any:
    """The value ``f`` should hold after :func:`other_value` was set (as the dataclass stores it)."""
    value = other_value(f)
    if f.name == "faults.schedule":
        return tuple((item["kind"], item["at"]) for item in value)
    return value


def stored(config: Any, f: ConfigField) -> Any:
    """The value of ``f`` in ``config`` (a PlannerConfig for a planner field, else AppSettings)."""
    value = config
    for key in f.path[1:] if f.path[0] == "server" else f.path:
        value = getattr(value, key)
    if f.name == "faults.schedule":
        return tuple((s.kind, s.at) for s in value)
    return value


def nested(fields: list[ConfigField], drop: int = 0) -> dict[str, Any]:
    """``{section: {key: other value}}`` of ``fields`` (their paths without the first ``drop`` keys)."""
    out: dict[str, Any] = {}
    for f in fields:
        node = out
        for key in f.path[drop:-1]:
            node = node.setdefault(key, {})
        node[f.path[-1]] = other_value(f)
    return out


def toml_text(data: dict[str, Any], table: str = "") -> str:
    """``data`` as TOML: the scalars of a table, then its sub-tables."""

    def value(v: Any) -> str:
        if isinstance(v, dict):
            return "{ " + ", ".join(f"{k} = {value(x)}" for k, x in v.items()) + " }"
        if isinstance(v, tuple | list):
            return "[" + ", ".join(value(x) for x in v) + "]"
        return render_value(v)

    scalars = [f"{k} = {value(v)}" for k, v in data.items() if not isinstance(v, dict)]
    text = (f"[{table}]\n" if table and scalars else "") + "".join(line + "\n" for line in scalars)
    for k, v in data.items():
        if isinstance(v, dict):
            text += toml_text(v, f"{table}.{k}" if table else k)
    return text


def argv(fields: list[ConfigField]) -> list[str]:
    """The generated flag of every field with its other value."""
    out: list[str] = []
    for f in fields:
        value = other_value(f)
        words = [str(v) for v in value] if isinstance(value, tuple) else [render_value(value).strip('"')]
        out += [f"--{f.name}", *words]
    return out


PLANNER = config_fields(PlannerConfig)
SERVER = [f for f in config_fields(AppSettings, ("server",)) if f.path[1] not in ("planner", "devices", "faults")]
DEVICES = config_fields(DeviceConfig, ("devices",))
FAULTS = config_fields(FaultConfig, ("faults",))

NOT_ON_THE_COMMAND_LINE: dict[str, str] = {
    "devices.cell.arm.T_flange_camera": "a 4x4 matrix: the server file (a real cell's comes from its cell file)",
    **{f.name: "fault injection is a test facility: the server file's [faults] or the REST body" for f in FAULTS},
}
"""Fields with no flag, and why."""

NOT_OVER_REST: dict[str, str] = {
    **{f.name: "the server's own settings, not a session's" for f in SERVER},
    **{
        f.name: "the server's simulated cell; a session chooses model, seed and camera in the body's own fields"
        for f in DEVICES
    },
    **{f.name: "a session's faults live in its devices, not in a config it reports" for f in FAULTS},
}
"""Fields no REST body sets under their dotted name, and why (the planner config is settable, but see below)."""

DERIVED_IN_A_SIMULATED_SESSION: dict[str, str] = {
    "noise.depth_std": "the simulated cell sets it from its camera model (devices.planner_noise.noise_config)",
    "noise.depth_z2": "the simulated cell sets it from its camera model (devices.planner_noise.noise_config)",
}
"""Planner fields the create body accepts but a simulated session's cell then replaces (NoiseConfig's docstring)."""


def test_the_exclusions_name_real_fields_and_the_planner_has_none() -> None:
    names = {f.name for f in [*PLANNER, *SERVER, *DEVICES, *FAULTS]}
    assert set(NOT_ON_THE_COMMAND_LINE) <= names and set(NOT_OVER_REST) <= names
    assert not any(f.name in NOT_ON_THE_COMMAND_LINE or f.name in NOT_OVER_REST for f in PLANNER)
    assert len(PLANNER) >= 80 and len(SERVER) >= 30 and len(DEVICES) >= 40  # the walk found the nested sections
    assert all(other_value(f) != f.default for f in [*PLANNER, *SERVER, *DEVICES, *FAULTS])


def test_every_planner_setting_by_its_flag(tmp_path: Path) -> None:
    for command in ("scan", "profile", "bench"):
        head = ["bench", "--models", "mug"] if command == "bench" else [command, "--model", "mug"]
        args = build_parser().parse_args([*head, *argv(PLANNER)])
        config = planner_config_from_args(args)
        wrong = [f.name for f in PLANNER if stored(config, f) != expected(f)]
        assert wrong == [], command


def test_every_planner_setting_by_its_flag_under_serve() -> None:
    fields = [dataclasses.replace(f, path=("planner", *f.path)) for f in PLANNER]
    args = build_parser().parse_args(["serve", *argv(fields)])
    settings = serve.settings_from_flags(args)
    assert [f.name for f in PLANNER if stored(settings.planner, f) != expected(f)] == []


def test_every_planner_setting_from_toml(tmp_path: Path) -> None:
    path = tmp_path / "planner.toml"
    path.write_text(toml_text(nested(PLANNER)))
    config = PlannerConfig.from_toml(path)
    assert [f.name for f in PLANNER if stored(config, f) != expected(f)] == []
    args = build_parser().parse_args(["scan", "--model", "mug", "--config", str(path)])  # nbv scan --config
    assert planner_config_from_args(args) == config


def test_every_planner_setting_over_rest(tmp_path: Path) -> None:
    """The create body's ``config`` takes every field under its dotted name and the session's config holds it."""
    settings = AppSettings(viser_port=0, scene=False, workers=False, journal=False, data_dir=tmp_path / "data")
    with TestClient(create_app(settings), base_url="http://127.0.0.1") as client:
        r = client.post("/api/sessions", json={"model": "l-block", "config": nested(PLANNER)})
        assert r.status_code == 201, r.text
        sid = r.json()["id"]
        exported = client.get(f"/api/sessions/{sid}/export")
        assert exported.status_code == 200, exported.text
        config = PlannerConfig.from_dict(exported.json()["config"])
        wrong = [f.name for f in PLANNER if stored(config, f) != expected(f)]
        assert set(wrong) == set(DERIVED_IN_A_SIMULATED_SESSION)
        one = {"scoring": {"rank_base": 0.25}}
        r = client.post("/api/sessions", json={"model": "l-block", "config": {"scoring": {"rank_bse": 0.25}}})
        assert r.status_code == 422 and "scoring.rank_bse: unknown setting" in r.text
        r = client.post("/api/sessions", json={"model": "l-block", "config": {"partitions": {"stall_growth": 0.01}}})
        assert r.status_code == 422 and "partitions.stall_growth: removed setting" in r.text
        assert client.post("/api/sessions", json={"model": "l-block", "config": one}).status_code == 201


def test_every_server_and_device_setting_by_its_serve_flag() -> None:
    flagged = [f for f in [*SERVER, *DEVICES, *FAULTS] if f.name not in NOT_ON_THE_COMMAND_LINE]
    args = build_parser().parse_args(["serve", *argv(flagged)])
    settings = serve.settings_from_flags(args)
    wrong = [f.name for f in flagged if stored(settings, f) != expected(f)]
    assert wrong == []


def test_every_server_device_and_fault_setting_from_toml(tmp_path: Path) -> None:
    path = tmp_path / "server.toml"
    path.write_text(toml_text(nested([*SERVER, *DEVICES, *FAULTS])))
    settings = load_settings(path)
    wrong = [f.name for f in [*SERVER, *DEVICES, *FAULTS] if stored(settings, f) != expected(f)]
    assert wrong == []


def test_the_old_short_flags_are_aliases_of_the_generated_ones() -> None:
    words = {
        "--views": "7",
        "--resolution": "0.02",
        "--candidates": "60",
        "--parallels": "4",
        "--partitions": "6",
        "--t-min": "2",
        "--t-max": "9",
        "--gamma": "0.03",
        "--working-distance": "0.4",
        "--search": "exhaustive",
        "--growth-threshold": "0.05",
        "--move-cost-weight": "0.5",
    }
    assert {a for names in PLANNER_ALIASES.values() for a in names} == set(words)
    config = planner_config_from_args(
        build_parser().parse_args(["scan", "--model", "mug", *[w for kv in words.items() for w in kv]])
    )
    for name, (alias,) in PLANNER_ALIASES.items():
        section, key = name.split(".")
        assert str(getattr(getattr(config, section), key)) == words[alias], alias
    args = build_parser().parse_args(["serve", "--port", "8100", "--dry-run", "--cors-origin", "http://a.b"])
    settings = serve.settings_from_flags(args)
    assert (settings.port, settings.dry_run, settings.cors_origins) == (8100, True, ("http://a.b",))


def test_a_flag_keeps_the_file_and_the_seed_unless_it_sets_them(tmp_path: Path) -> None:
    path = tmp_path / "p.toml"
    path.write_text("[voxel]\nresolution = 0.02\n[cluster]\nt_max = 12\n")
    args = build_parser().parse_args(["scan", "--model", "mug", "--config", str(path), "--t-max", "9", "--seed", "4"])
    config = planner_config_from_args(args)
    assert (config.voxel.resolution, config.cluster.t_max, config.cluster.seed) == (0.02, 9, 4)
    args = build_parser().parse_args(["scan", "--model", "mug", "--seed", "4", "--cluster.seed", "5"])
    assert planner_config_from_args(args).cluster.seed == 5


@pytest.mark.parametrize(
    ("words", "message"),
    [
        (["--voxel.resolution", "-1"], "voxel.resolution: must be > 0"),
        (["--cluster.t_min", "9", "--cluster.t_max", "3"], r"cluster.t_min \(9\) must be <= cluster.t_max \(3\)"),
    ],
)
def test_a_bad_flag_value_is_refused_by_the_dataclass(
    capsys: pytest.CaptureFixture[str], tmp_path: Path, words: list[str], message: str
) -> None:
    import re

    assert main(["scan", "--model", "mug", *words, "--out", str(tmp_path / "o")]) == 2
    err = capsys.readouterr().err
    assert re.search(message, err) and "\n" not in err.strip()
    assert not (tmp_path / "o").exists()


@pytest.mark.parametrize("words", [["--voxel.resolutio", "0.02"], ["--voxel.floor", "maybe"], ["--stall-growth", "1"]])
def test_an_unknown_flag_or_a_bad_word_is_an_argparse_error(words: list[str]) -> None:
    with pytest.raises(SystemExit):
        build_parser().parse_args(["scan", "--model", "mug", *words])
    for name in REMOVED:  # the removed settings have no flag
        with pytest.raises(SystemExit):
            build_parser().parse_args(["scan", "--model", "mug", f"--{name}", "1"])


def test_the_help_shows_the_docstring_and_the_default(capsys: pytest.CaptureFixture[str]) -> None:
    with pytest.raises(SystemExit):
        build_parser().parse_args(["scan", "--help"])
    text = " ".join(capsys.readouterr().out.split())
    doc = first_sentence(next(f.doc for f in PLANNER if f.name == "voxel.resolution"))
    assert f"--voxel.resolution FLOAT, --resolution FLOAT {doc} (default: 0.01)" in text
    assert "--cluster.search {fast,exhaustive}, --search {fast,exhaustive}" in text


def test_the_configuration_pages_are_the_generated_ones() -> None:
    """docs/configuration.md and configuration-server.md are ``python -m nbv.config_doc docs``'s output (run it
    after changing a field)."""
    pages = config_doc.render_pages()
    assert set(pages) == {"configuration.md", "configuration-server.md"}
    for name, text in pages.items():
        assert (REPO / "docs" / name).read_text() == text, f"docs/{name} is stale: python -m nbv.config_doc docs"
    for f in PLANNER:
        assert f"| `{f.path[-1]}` |" in pages["configuration.md"]
    for f in [*SERVER, *DEVICES, *FAULTS]:
        assert f"| `{f.path[-1]}` |" in pages["configuration-server.md"]
    assert "| `--voxel.resolution`, `--resolution` |" in pages["configuration.md"]
    assert "`--planner.voxel.resolution` for serve" in pages["configuration.md"]


def test_every_field_is_documented() -> None:
    assert [f.name for f in [*PLANNER, *SERVER, *DEVICES, *FAULTS] if not f.doc] == []


def test_argparse_namespace_has_no_stray_config_attributes() -> None:
    """Only the flags given reach the config: an empty command line is the config's defaults."""
    args = build_parser().parse_args(["scan", "--model", "mug", "--seed", "0"])
    assert planner_config_from_args(args) == PlannerConfig()
    assert isinstance(args, argparse.Namespace) and getattr(args, "voxel.resolution") is None
