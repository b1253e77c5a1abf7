"""The one config object: YAML, CLI overrides and slider-style sets share one validation."""

from __future__ import annotations

from pathlib import Path

import pytest

from app.config import Config, ConfigError


def test_defaults_are_the_papers_constants() -> None:
    c = Config()
    assert c.consciousness.tracking_threshold_m == 0.30
    assert c.consciousness.island_threshold_m == 0.10
    assert c.consciousness.presence_threshold == 0.8
    assert c.consciousness.rolling_average_weight == 0.9
    assert c.consciousness.frames_for_presence == 5
    assert c.detector.confidence == 0.4
    assert c.server.host == "127.0.0.1"
    c.validate()


def test_yaml_round_trip(tmp_path) -> None:
    c = Config()
    c.set("consciousness.tracking_threshold_m", 0.25)
    c.set("consciousness.mode", "seed")
    c.set("lidar.noise_std_m", 0.02)
    p = c.save(tmp_path / "cfg.yaml")
    d = Config.load(p)
    assert d.to_dict() == c.to_dict()


def test_overrides_and_types(tmp_path) -> None:
    c = Config.load(None, ["slam.resolution_m=0.1", "consciousness.legs=false", "detector.threads=1", "sim.world=x.yaml"])
    assert c.slam.resolution_m == 0.1 and c.consciousness.legs is False and c.detector.threads == 1
    assert c.sim.world == "x.yaml"


@pytest.mark.parametrize(
    "key,value,msg",
    [
        ("consciousness.presence_threshold", 1.5, "outside"),
        ("consciousness.mode", "fancy", "not one of"),
        ("detector.threads", 1.5, "expected a int"),
        ("lidar.noise_std_m", float("nan"), "expected a float"),
        ("nosuch.key", 1, "unknown config section"),
        ("slam.nosuch", 1, "unknown config key"),
    ],
)
def test_bad_values_are_refused_with_the_key(key, value, msg) -> None:
    c = Config()
    with pytest.raises(ConfigError, match=msg):
        c.set(key, value)


def test_bad_files(tmp_path) -> None:
    (tmp_path / "bad.yaml").write_text("sim: [unclosed\n")
    with pytest.raises(ConfigError, match="malformed YAML"):
        Config.load(tmp_path / "bad.yaml")
    (tmp_path / "unk.yaml").write_text("foo: {}\n")
    with pytest.raises(ConfigError, match="unknown section 'foo'"):
        Config.load(tmp_path / "unk.yaml")
    (tmp_path / "range.yaml").write_text("lidar:\n  beams: -3\n")
    with pytest.raises(ConfigError, match="lidar.beams"):
        Config.load(tmp_path / "range.yaml")
    with pytest.raises(ConfigError, match="cannot read"):
        Config.load(tmp_path / "missing.yaml")


def test_config_reference_is_up_to_date() -> None:
    """docs/config.md is generated from the config metadata: regenerate it with scripts/gen_config_doc.py."""
    import importlib.util
    from pathlib import Path

    root = Path(__file__).resolve().parents[1]
    spec = importlib.util.spec_from_file_location("gen_config_doc", root / "scripts" / "gen_config_doc.py")
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    assert (root / "docs" / "config.md").read_text(encoding="utf-8") == mod.render()


def test_every_live_field_has_a_range_or_choices() -> None:
    """Sliders need bounds: a live numeric field without min/max could not be refused when out of range."""
    for path, f, value in Config().iter_fields():
        if f.metadata.get("live") and isinstance(value, (int, float)) and not isinstance(value, bool):
            assert f.metadata.get("min") is not None and f.metadata.get("max") is not None, path


def test_project_relative_names_no_machine_folder(tmp_path):
    """What a model card writes down: paths inside the project relative to it, others as given."""
    from app.config import PROJECT_ROOT, project_relative

    assert project_relative(PROJECT_ROOT / "runs" / "detector" / "data.yaml") == str(Path("runs/detector/data.yaml"))
    assert project_relative("datasets/sim") == str(Path("datasets/sim"))
    assert project_relative(tmp_path / "elsewhere") == str(tmp_path / "elsewhere")
