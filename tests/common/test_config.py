from dataclasses import dataclass, field
from typing import Literal, Optional

import pytest

from common.config import ConfigError, dump_config, from_dict, load_config, replace_checked
from simulator import SimulatorConfig


@dataclass(frozen=True)
class Inner:
    rate_hz: float = 1.0
    mode: Literal["a", "b"] = "a"


@dataclass(frozen=True)
class Outer:
    name: str
    inner: Inner = field(default_factory=Inner)
    sizes: tuple[int, ...] = (1, 2)
    note: Optional[str] = None


def test_nested_values_and_types(tmp_path):
    p = tmp_path / "c.yaml"
    p.write_text("name: x\ninner: {rate_hz: 3, mode: b}\nsizes: [4, 5, 6]\n")
    cfg = load_config(Outer, p)
    assert cfg == Outer("x", Inner(3.0, "b"), (4, 5, 6))
    assert isinstance(cfg.inner.rate_hz, float)


@pytest.mark.parametrize("text, words", [
    ("name: x\ncolour: red\n", "colour: unknown key"),
    ("name: x\ninner: {rate: 2}\n", "inner.rate: unknown key"),
    ("name: x\ninner: {rate_hz: fast}\n", "inner.rate_hz: expected a number"),
    ("name: x\ninner: {mode: c}\n", "inner.mode: expected one of"),
    ("name: x\nsizes: [1, true]\n", r"sizes\[1\]: expected an integer"),
    ("inner: {}\n", "name: required key is missing"),
    ("- 1\n- 2\n", "expected a mapping"),
    ("name: [unclosed\n", "not valid YAML"),
])
def test_errors_name_the_file_and_key(tmp_path, text, words):
    p = tmp_path / "bad.yaml"
    p.write_text(text)
    with pytest.raises(ConfigError, match=words) as err:
        load_config(Outer, p)
    assert str(p) in str(err.value)


def test_missing_file_is_a_clear_error(tmp_path):
    with pytest.raises(ConfigError, match="cannot read config file"):
        load_config(Outer, tmp_path / "nope.yaml")


def test_simulator_config_validates_values(tmp_path):
    p = tmp_path / "sim.yaml"
    p.write_text("pos_threshold: 0.0\n")
    with pytest.raises(ConfigError, match="pos_threshold: expected a number >= threshold_min"):
        load_config(SimulatorConfig, p)
    p.write_text("refractory_us: -5\n")
    with pytest.raises(ConfigError, match="refractory_us"):
        load_config(SimulatorConfig, p)
    p.write_text("shot_noise_rate: 3\n")
    with pytest.raises(ConfigError, match="shot_noise_rate: unknown key"):
        load_config(SimulatorConfig, p)


def test_dump_then_load_round_trip(tmp_path):
    cfg = SimulatorConfig(threshold_sigma=0.03, refractory_us=100, log_mode="linlog")
    p = tmp_path / "resolved.yaml"
    p.write_text(dump_config(cfg))
    assert load_config(SimulatorConfig, p) == cfg
    assert replace_checked(cfg, leak_rate_hz=2) == SimulatorConfig(**{**cfg.__dict__, "leak_rate_hz": 2.0})
    with pytest.raises(ConfigError, match="nope: unknown key"):
        replace_checked(cfg, nope=1)
    assert from_dict(SimulatorConfig, {}) == SimulatorConfig()


def test_shipped_simulator_configs_load():
    from pathlib import Path

    from simulator.sensor_presets import load_sensor, read_sensor

    files = sorted((Path(__file__).resolve().parents[2] / "configs" / "sensors").glob("*.yaml"))
    assert len(files) >= 5
    for f in files:
        load_sensor(f, tuple(read_sensor(f)[1]))          # with every effect it supplies
    assert load_sensor(files[0].with_name("ideal.yaml")) == SimulatorConfig()


def test_yaml_merge_keys_work_and_duplicates_are_still_refused(tmp_path):
    from common.config import read_yaml_mapping

    path = tmp_path / "c.yaml"
    path.write_text("base: &b\n  x: 1\n  y: 2\nother:\n  <<: *b\n  y: 3\n")
    assert read_yaml_mapping(path) == {"base": {"x": 1, "y": 2}, "other": {"x": 1, "y": 3}}
    path.write_text("other:\n  y: 2\n  y: 3\n")
    with pytest.raises(ConfigError, match="'y' appears twice"):
        read_yaml_mapping(path)


def test_an_error_never_prints_an_unbounded_value(tmp_path):
    """A huge value (a YAML anchor can expand without bound) in a field that wants a number: the message
    shows 80 characters of it and says how long it is."""
    from common.config import load_config

    @dataclass(frozen=True)
    class C:
        n: int = 1

    row = "[" + ", ".join(["xxxxxxxx"] * 200) + "]"
    (tmp_path / "d.yaml").write_text("n: [&r " + row + ", " + ", ".join(["*r"] * 200) + "]\n")
    with pytest.raises(ConfigError) as exc:
        load_config(C, tmp_path / "d.yaml")
    msg = str(exc.value)
    assert "n: expected an integer, got [['xxxxxxxx'" in msg and "characters) (list)" in msg and len(msg) < 300
