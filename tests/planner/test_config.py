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
        ({"partitions": {"sectors": True}}, "partitions.sectors: expected a number, got True"),
        ({"cluster": {"max_iter": 2.5}}, "cluster.max_iter: must be an integer >= 1, got 2.5"),
        ({"cluster": {"min_points_per_component": 0}}, "cluster.min_points_per_component: must be an integer >= 1"),
        ({"cluster": {"seed": -1}}, "cluster.seed: must be an integer >= 0"),
        ({"registration": {"max_iterations": 0.5}}, "registration.max_iterations: must be an integer >= 1"),
        ({"partitions": {"revisit_deg": 180}}, r"partitions.revisit_deg: must be in \[0, 180\)"),
        ({"candidates": {"aim_hold_voxels": -1}}, "candidates.aim_hold_voxels: must be an integer >= 0"),
        ({"candidates": {"aim_hold_voxels": 0.5}}, "candidates.aim_hold_voxels: must be an integer >= 0"),
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


@pytest.mark.parametrize(
    ("section", "field"),
    [("partitions", "sectors"), ("candidates", "count"), ("cluster", "t_max"), ("termination", "max_views")],
)
def test_a_bool_is_not_a_count_even_when_built_directly(section: str, field: str) -> None:
    from dataclasses import replace

    part = getattr(PlannerConfig(), section)
    with pytest.raises(ValueError, match=f"{section}.{field}: must be an integer"):
        replace(part, **{field: True})


def test_whole_floats_still_set_integer_fields() -> None:
    cfg = PlannerConfig.from_dict({"cluster": {"max_iter": 50.0, "seed": 3.0}})
    assert cfg.cluster.max_iter == 50 and isinstance(cfg.cluster.max_iter, int) and cfg.cluster.seed == 3


@pytest.mark.parametrize(
    ("section", "key", "value"),
    [("voxel", "frontier_max_looks", 0), ("scoring", "max_incidence_deg", 90.0), ("partitions", "stall_growth", 0.0)],
)
def test_a_removed_setting_loads_from_a_journal_and_is_refused_from_a_user(section: str, key: str, value: float) -> None:
    """Journals written before the removal carry the key in every config: they still load (the key ignored);
    a person who sets it is told it was removed, and a misspelt key is still unknown."""
    recorded = PlannerConfig().to_dict()
    recorded[section][key] = value
    recorded["voxel"]["resolution"] = 0.02
    loaded = PlannerConfig.from_journal(recorded)
    assert loaded.voxel.resolution == 0.02 and not hasattr(getattr(loaded, section), key)
    with pytest.raises(ValueError, match=rf"{section}\.{key}: removed setting \(.*measured"):
        PlannerConfig.from_dict({section: {key: value}})
    with pytest.raises(ValueError, match=rf"{section}\.{key}: removed setting"):
        PlannerConfig().replace(**{section: {key: value}})
    with pytest.raises(ValueError, match=rf"{section}\.{key}x: unknown setting"):
        PlannerConfig.from_journal({section: {f"{key}x": value}})
