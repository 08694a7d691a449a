"""Named sensors (configs/sensors/<name>.yaml): a sensor's pixel parameters, plus the values of the
optional effects it can supply, each applied only where a scene (or `e4dgs simulate --effects`)
calls for it:

    pos_threshold: 0.25          # pixel parameters: SimulatorConfig fields, always applied
    ...
    effects:                     # optional effects: applied when named
      latency: {latency_us: 60, latency_jitter_us: 20}
      bandwidth: {max_event_rate_hz: 1.2e7, max_readout_delay_us: 1000}

`sensor_dict(name, effects)` is the SimulatorConfig mapping of a sensor with the named effects on;
every field is written out, so merged over a scene's own `sensor:` it replaces it whole.
"""
from __future__ import annotations

from pathlib import Path
from typing import Iterable

from common.config import ConfigError, from_dict, read_yaml_mapping, to_dict
from simulator.config import SimulatorConfig

# The optional effects and the SimulatorConfig fields each one sets.
EFFECTS = {
    "latency": ("latency_us", "latency_jitter_us"),
    "readout": ("readout_period_us",),
    "bandwidth": ("max_event_rate_hz", "max_readout_delay_us"),
    "on_off_mismatch": ("pos_threshold_sigma", "neg_threshold_sigma"),
}


def sensor_file(name: str | Path) -> Path:
    """A sensor YAML: a file path, or a shipped sensor's name (configs/sensors/<name>.yaml)."""
    from common.config_files import find, shipped_names

    found = find("sensors", name)
    if found is None:
        raise ConfigError(f"unknown sensor {str(name)!r} (no such file, nor a shipped sensor of that name; "
                          f"shipped: {', '.join(shipped_names('sensors'))})")
    return found


def read_sensor(name: str | Path) -> tuple[dict, dict[str, dict]]:
    """(pixel parameters, {effect: its fields}) of a sensor YAML; ConfigError names the file and key."""
    path = sensor_file(name)
    data = read_yaml_mapping(path)
    effects = data.pop("effects", None) or {}
    if not isinstance(effects, dict):
        raise ConfigError(f"{path}: effects: expected a mapping {{effect: {{field: value}}}}, got {effects!r}")
    for effect, values in effects.items():
        if effect not in EFFECTS:
            raise ConfigError(f"{path}: effects.{effect}: not an effect (expected any of {', '.join(EFFECTS)})")
        if not isinstance(values, dict):
            raise ConfigError(f"{path}: effects.{effect}: expected a mapping of its fields, got {values!r}")
        for key in values:
            if key not in EFFECTS[effect]:
                raise ConfigError(f"{path}: effects.{effect}.{key}: not a field of this effect "
                                  f"(expected any of {', '.join(EFFECTS[effect])})")
        if any(key in data for key in EFFECTS[effect]):
            raise ConfigError(f"{path}: effects.{effect}: its fields are also set among the pixel parameters; keep one")
    try:
        from_dict(SimulatorConfig, data)
        for values in effects.values():
            from_dict(SimulatorConfig, {**data, **values})
    except ConfigError as exc:
        raise ConfigError(f"{path}: {exc}") from None
    return data, effects


def sensor_dict(name: str | Path, effects: Iterable[str] = ()) -> dict:
    """Every SimulatorConfig field of sensor `name` with `effects` on (each must be one it supplies)."""
    base, supplied = read_sensor(name)
    values = dict(base)
    for effect in effects:
        if effect not in EFFECTS:
            raise ConfigError(f"effect {effect!r}: expected any of {', '.join(EFFECTS)}")
        if effect not in supplied:
            raise ConfigError(f"sensor {str(name)!r} supplies no values for the effect {effect!r} "
                              f"(it supplies: {', '.join(supplied) or 'none'})")
        values.update(supplied[effect])
    return to_dict(from_dict(SimulatorConfig, values))


def load_sensor(name: str | Path, effects: Iterable[str] = ()) -> SimulatorConfig:
    """The SimulatorConfig of sensor `name` with `effects` on."""
    return from_dict(SimulatorConfig, sensor_dict(name, effects))
