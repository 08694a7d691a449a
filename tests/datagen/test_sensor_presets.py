"""Named sensors (configs/sensors/, simulator.sensor_presets) and datasets seen through them
(`<preset>@<sensor>`): the sensor replaces a scene's own whole, effects apply only where a scene
declares them, errors name the file and key, and folders made before the later sensor fields keep
their identity."""
from dataclasses import replace

import pytest

from common.config import ConfigError, to_dict
from datagen.config import load_preset, resolve_scene
from datagen.scene_folder import config_fingerprint
from simulator.config import LATER_FIELDS, SimulatorConfig
from simulator.sensor_presets import EFFECTS, load_sensor, read_sensor, sensor_dict


def test_dataset_under_a_sensor_replaces_every_scene_sensor():
    own = resolve_scene("garage", load_preset("quick").scene("garage"))
    assert own.sensor.shot_noise_rate_hz > 0                      # garage declares shot noise itself
    seen = resolve_scene("garage", load_preset("quick@davis346").scene("garage"))
    assert seen.sensor == load_sensor("davis346") and seen.sensor_preset == "davis346"
    assert seen.sensor.shot_noise_rate_hz == 0                    # replaced whole, not merged
    both = load_preset("quick@davis346@noise2")
    cfg = resolve_scene("hinge", both.scene("hinge"))
    assert cfg.sensor_seed == 2 and cfg.sensor == load_sensor("davis346")
    assert config_fingerprint(cfg) != config_fingerprint(resolve_scene("hinge", load_preset("quick").scene("hinge")))


def test_unknown_sensor_names_itself():
    with pytest.raises(ConfigError, match="unknown sensor 'davis999'.*shipped: .*davis346"):
        load_preset("quick@davis999")


def test_effects_only_where_the_scene_declares_them():
    base, supplied = read_sensor("davis346")
    assert "bandwidth" in supplied
    plain = resolve_scene("hinge", {"sensor_preset": "davis346"})
    assert not plain.sensor.has_readout
    limited = resolve_scene("hinge", {"sensor_preset": "davis346", "sensor_effects": ["bandwidth"]})
    assert limited.sensor.max_event_rate_hz == supplied["bandwidth"]["max_event_rate_hz"] > 0
    assert replace(limited.sensor, **{k: LATER_FIELDS[k] for k in EFFECTS["bandwidth"]}) == plain.sensor
    with pytest.raises(ConfigError, match="supplies no values for the effect 'readout'"):
        resolve_scene("hinge", {"sensor_preset": "davis346", "sensor_effects": ["readout"]})
    with pytest.raises(ConfigError, match="sensor_effects: 'latencyy' is not an effect"):
        resolve_scene("hinge", {"sensor_effects": ["latencyy"]})


def test_sensor_file_errors_name_the_key(tmp_path):
    bad = tmp_path / "s.yaml"
    for text, expected in (("pos_threshold: 0.3\neffects: {warp: {latency_us: 1}}\n", "effects.warp: not an effect"),
                           ("effects: {latency: {readout_period_us: 5}}\n", "effects.latency.readout_period_us: not a field"),
                           ("latency_us: 3\neffects: {latency: {latency_us: 5}}\n", "also set among the pixel parameters"),
                           ("effects: {latency: {latency_us: -5}}\n", "latency_us"),
                           ("effects: [latency]\n", "effects: expected a mapping")):
        bad.write_text(text)
        with pytest.raises(ConfigError, match=expected) as info:
            sensor_dict(bad, ())
        assert str(bad) in str(info.value)


def test_later_fields_off_keep_the_fingerprint():
    """A folder generated before the readout and shot-noise fields existed keeps its identity while
    they are off; switching one on is another dataset."""
    cfg = resolve_scene("hinge", load_preset("quick").scene("hinge"))
    assert to_dict(cfg.sensor).keys() >= LATER_FIELDS.keys()
    fp = config_fingerprint(cfg)
    for key, off in LATER_FIELDS.items():
        assert getattr(SimulatorConfig(), key) == off
        on = 0.3 if off is None or isinstance(off, float) else 7
        assert config_fingerprint(replace(cfg, sensor=replace(cfg.sensor, **{key: on}))) != fp, key


@pytest.mark.parametrize("name", ["davis346", "imx636", "dvxplorer"])
def test_shipped_real_sensors_load_with_every_effect_they_supply(name):
    base, supplied = read_sensor(name)
    cfg = load_sensor(name, tuple(supplied))
    assert cfg.pos_threshold > 0 and cfg.refractory_us > 0
    assert all(k in EFFECTS for k in supplied)


def test_a_dataset_seen_by_two_sensors_is_refused():
    with pytest.raises(ConfigError, match="names two sensors"):
        load_preset("quick@ideal@davis346")
