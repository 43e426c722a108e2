"""Configuration: the paper's defaults, nested overrides, clear errors."""

import pytest

from planner.config import PlannerConfig


def test_defaults_are_the_papers() -> None:
    cfg = PlannerConfig()
    assert cfg.voxel.resolution == 0.01
    assert cfg.candidates.count == 400
    assert cfg.partitions.sectors == 4
    assert (cfg.cluster.t_min, cfg.cluster.t_max) == (5, 50)
    assert cfg.scoring.rank_base == 0.5


def test_nested_override_and_round_trip(tmp_path) -> None:
    cfg = PlannerConfig().replace(voxel={"resolution": 0.005}, cluster={"t_max": 20})
    assert cfg.voxel.resolution == 0.005 and cfg.cluster.t_max == 20 and cfg.cluster.t_min == 5
    assert PlannerConfig.from_dict(cfg.to_dict()) == cfg
    path = tmp_path / "c.toml"
    path.write_text("[voxel]\nresolution = 0.02\n[partitions]\nsectors = 6\n")
    loaded = PlannerConfig.from_toml(path)
    assert loaded.voxel.resolution == 0.02 and loaded.partitions.sectors == 6


@pytest.mark.parametrize(
    ("data", "message"),
    [
        ({"voxel": {"resolution": 0}}, "voxel.resolution: must be > 0"),
        ({"voxel": {"resolution": -0.01}}, "voxel.resolution"),
        ({"cluster": {"t_min": 10, "t_max": 5}}, r"cluster.t_min \(10\) must be <= cluster.t_max \(5\)"),
        ({"termination": {"max_views": 0}}, "termination.max_views"),
        ({"voxel": {"colour": 1}}, "voxel.colour: unknown setting"),
        ({"nope": {}}, "nope: unknown setting"),
        ({"candidates": {"count": "many"}}, "candidates.count: expected a number"),
        ({"scoring": {"area": "guess"}}, "scoring.area"),
    ],
)
def test_invalid_settings_name_the_field(data: dict, message: str) -> None:
    with pytest.raises(ValueError, match=message):
        PlannerConfig.from_dict(data)


def test_bad_toml_is_a_value_error(tmp_path) -> None:
    path = tmp_path / "bad.toml"
    path.write_text("[voxel\nresolution = ")
    with pytest.raises(ValueError, match="invalid TOML"):
        PlannerConfig.from_toml(path)
