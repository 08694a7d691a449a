"""Scene and dataset configuration (pure Python; no bpy).

Each scene has a YAML file `blender_scenes/<name>.yaml` declaring what it calls for. A preset
(`configs/datasets/<preset>.yaml`) lists the scenes it covers and overrides values for all of them
(e.g. a shorter clip). The resolved config, scene YAML with the preset's overrides merged in, is
written to `<scene>/scene.yaml`.
"""
from __future__ import annotations

import re

from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Mapping


from common.config import ConfigError, from_dict, read_yaml_mapping
from scene_format.config import SceneConfig, deep_merge, expand_sensor_preset, parse_scene, read_scene_yaml

ROOT = Path(__file__).resolve().parent.parent
SCENES_DIR = ROOT / "blender_scenes"
PRESETS_DIR = ROOT / "configs" / "datasets"
SCENE_NAMES = ("lego", "rubiks_cube", "mc_toy", "hinge", "cubes", "capsule", "restroom", "garage")


@dataclass(frozen=True)
class PresetConfig:
    scenes: tuple[str, ...] = SCENE_NAMES  # the scenes the preset generates
    overrides: dict[str, Any] = field(default_factory=dict)  # merged into every scene's YAML
    # per scene, merged after `overrides` into that scene's YAML: {scene: {key: value}}
    scene_overrides: dict[str, dict[str, Any]] = field(default_factory=dict)

    def __post_init__(self):
        for name in self.scene_overrides:
            if name not in self.scenes:
                raise ConfigError(f"scene_overrides.{name}: not one of the preset's scenes ({', '.join(self.scenes)})")

    def scene(self, name: str) -> dict[str, Any]:
        """The overrides of one scene: the preset's, then the scene's own."""
        return deep_merge(self.overrides, self.scene_overrides.get(name, {}))


def file_scene_name(path: Path) -> str:
    """A scene file's scene (and folder) name: its stem with anything but letters, digits, - and _ as _."""
    import re

    return re.sub(r"[^A-Za-z0-9_-]", "_", Path(path).stem) or "scene"


def builtin_builder(cfg: SceneConfig, source: str | Path = "scene") -> str:
    """The built-in builder module of a scene built in code (source.builtin, else its name); ConfigError
    naming `source` when there is none (a scene YAML copied under a new name without saying which)."""
    builder = cfg.source.builtin or cfg.name
    if not (SCENES_DIR / f"{builder}.py").exists():
        known = ", ".join(SCENE_NAMES)
        if cfg.source.builtin:
            raise ConfigError(f"{source}: source.builtin: {builder!r} is not a built-in scene (built-in: {known})")
        raise ConfigError(f"{source}: {cfg.name!r} is not a built-in scene (built-in: {known}); a scene YAML under its "
                          f"own name says what it is made from: source: {{builtin: cubes}} for a variant of a "
                          "built-in scene, or source: {file: my_scene.blend} for your own scene")
    return builder


def scene_yaml_path(name: str) -> Path:
    if name not in SCENE_NAMES and not (SCENES_DIR / f"{name}.yaml").exists():
        raise ConfigError(f"unknown scene {name!r}: expected one of {', '.join(SCENE_NAMES)}")
    return SCENES_DIR / f"{name}.yaml"


def preset_file(preset: str | Path) -> Path:
    """A dataset preset's YAML: a file path, or a name in configs/datasets/ (common.config_files)."""
    from common.config_files import find, shipped_names

    path = find("datasets", preset)
    if path is None:
        where = Path(preset) if Path(preset).suffix in (".yaml", ".yml") else PRESETS_DIR / f"{preset}.yaml"
        raise ConfigError(f"unknown dataset preset {str(preset)!r} (no {where}); known presets: "
                          f"{', '.join(shipped_names('datasets'))}")
    return path


NOISE_REALISATION = re.compile(r"^(?P<base>.+)@noise(?P<k>\d+)$")
UNDER_SENSOR = re.compile(r"^(?P<base>.+)@(?P<sensor>[A-Za-z][A-Za-z0-9_-]*)$")


def load_preset(preset: str | Path) -> PresetConfig:
    """A dataset preset by name or file. `<preset>@noise<k>` is that preset's k-th noise realisation:
    the same scenes with the event sensor's noise and mismatch seeded by k (`sensor_seed`), which the
    benchmark's `noise` seed axis trains on (data/<preset>@noise<k>). `<preset>@<sensor>` is the same
    scenes seen by the named sensor (configs/sensors/<sensor>.yaml, `sensor_preset`) in place of each
    scene's own, with the effects each scene declares (`sensor_effects`); the two combine,
    `quick@davis346@noise1`."""
    from dataclasses import replace

    m = NOISE_REALISATION.match(str(preset)) if not Path(preset).is_file() else None
    if m is not None:
        base = load_preset(m["base"])
        return replace(base, overrides={**base.overrides, "sensor_seed": int(m["k"])})
    m = UNDER_SENSOR.match(str(preset)) if not Path(preset).is_file() else None
    if m is not None:
        from simulator.sensor_presets import read_sensor

        read_sensor(m["sensor"])                  # an unknown or broken sensor: its own error, now
        base = load_preset(m["base"])
        if base.overrides.get("sensor_preset"):
            raise ConfigError(f"dataset {str(preset)!r}: names two sensors ({base.overrides['sensor_preset']} and "
                              f"{m['sensor']}); a dataset is seen by one")
        return replace(base, overrides={**base.overrides, "sensor_preset": m["sensor"]})
    path = preset_file(preset)
    data = read_yaml_mapping(path)        # its errors name the file already
    try:
        preset_cfg = from_dict(PresetConfig, data)
    except ConfigError as exc:
        raise ConfigError(f"{path}: {exc}") from None
    for name in preset_cfg.scenes:   # every scene must build with the preset's overrides: blame the right file
        try:
            resolve_scene(name, preset_cfg.scene(name))
        except ConfigError as exc:
            resolve_scene(name)           # the scene's own YAML is wrong: that error, naming it
            detail = str(exc).split(": ", 1)[1] if ": " in str(exc) else str(exc)
            raise ConfigError(f"{path}: overrides (applied to scene {name!r}): {detail}") from None
    return preset_cfg


def resolve_scene(name: str, overrides: Mapping[str, Any] | None = None,
                  scene_file: str | Path | None = None) -> SceneConfig:
    """Scene YAML (or `scene_file`) with `overrides` merged in, parsed strictly."""
    path = Path(scene_file) if scene_file else scene_yaml_path(name)
    cfg = parse_scene(expand_sensor_preset(deep_merge(read_scene_yaml(path), overrides or {}), path), path)
    if scene_file is None and cfg.name != name:
        raise ConfigError(f"{path}: name: expected {name!r}, got {cfg.name!r}")
    return cfg
