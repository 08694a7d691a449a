"""Scene and dataset configuration (pure Python; no bpy).

Each scene has a YAML file `blender_scenes/<name>.yaml` declaring what it calls for. A preset
(`configs/dataset_<preset>.yaml`) lists the scenes it covers and overrides values for all of them
(e.g. a shorter clip). The resolved config, scene YAML with the preset's overrides merged in, is
written to `<scene>/scene.yaml`.
"""
from __future__ import annotations

import copy
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Literal, Mapping

import yaml

from e4dgs.config import ConfigError, check_positive, from_dict
from simulator.config import SimulatorConfig

ROOT = Path(__file__).resolve().parent.parent
SCENES_DIR = ROOT / "blender_scenes"
PRESETS_DIR = ROOT / "configs"
SCENE_NAMES = ("lego", "rubiks_cube", "mc_toy", "hinge", "cubes", "capsule", "restroom", "garage")


@dataclass(frozen=True)
class RenderConfig:
    """engine: workbench (rasteriser, noise-free; default) | cycles | eevee. samples: anti-aliasing
    samples for workbench (1, 5, 8, 11, 16, 32), path-tracing samples for cycles, TAA samples for eevee."""
    engine: Literal["workbench", "cycles", "eevee"] = "workbench"
    samples: int = 8
    fps: float = 3000.0
    width: int = 346
    height: int = 260

    def __post_init__(self):
        check_positive(self, "samples", "fps", "width", "height")
        if self.engine == "workbench" and self.samples not in (1, 5, 8, 11, 16, 32):
            raise ConfigError(f"samples: workbench supports 1, 5, 8, 11, 16 or 32 samples, got {self.samples}")


@dataclass(frozen=True)
class CameraRigConfig:
    """Cameras uniformly spaced in azimuth on a spiral around `target`, at constant height.

    Camera k starts at azimuth azimuth0_deg + 360 k / n_cameras and turns by sweep_deg over the clip;
    its distance from the vertical axis through the target goes from radius to radius + radius_change.
    """
    n_cameras: int = 6
    radius: float = 4.0
    height: float = 1.5
    target: tuple[float, float, float] = (0.0, 0.0, 0.0)
    azimuth0_deg: float = 0.0
    sweep_deg: float = 30.0
    radius_change: float = 0.0
    fov_x_deg: float = 50.0

    def __post_init__(self):
        check_positive(self, "n_cameras", "radius", "fov_x_deg")
        if not self.fov_x_deg < 170:
            raise ConfigError(f"fov_x_deg: expected less than 170 degrees, got {self.fov_x_deg}")
        if not self.radius + self.radius_change > 0:
            raise ConfigError("radius_change: the spiral must keep a positive radius")


@dataclass(frozen=True)
class LightingConfig:
    """Workbench studio lighting, fixed in world space so every camera sees the same shading
    (`shading: flat` shows unlit texture colours)."""
    shading: Literal["studio", "flat"] = "studio"
    studio_light: str = "Default"
    rotate_z_deg: float = 30.0
    shadows: bool = True
    shadow_intensity: float = 0.4
    light_direction: tuple[float, float, float] = (0.4, -0.3, 0.85)
    cavity: bool = False
    background: tuple[float, float, float] = (0.05, 0.05, 0.06)  # linear RGB of the empty background
    exposure: float = 1.0  # linear gain on rendered radiance (a brighter or dimmer scene)

    def __post_init__(self):
        check_positive(self, "exposure")


@dataclass(frozen=True)
class FramesConfig:
    """keep_every: store RGB frames at every n-th rendered timestamp. test_every: of those, every
    n-th one per camera is held out for testing (llffhold)."""
    keep_every: int = 30
    test_every: int = 8

    def __post_init__(self):
        check_positive(self, "keep_every", "test_every")


@dataclass(frozen=True)
class SceneConfig:
    name: str
    kind: Literal["object", "room"]
    description: str = ""
    duration_s: float = 0.2
    motion_strength: float = 1.0
    seed: int = 0
    render: RenderConfig = field(default_factory=RenderConfig)
    camera: CameraRigConfig = field(default_factory=CameraRigConfig)
    lighting: LightingConfig = field(default_factory=LightingConfig)
    frames: FramesConfig = field(default_factory=FramesConfig)
    # motion-blur levels: name -> exposure time in milliseconds (empty: no blurred frames)
    blur_ms: dict[str, float] = field(default_factory=dict)
    sensor: SimulatorConfig = field(default_factory=SimulatorConfig)

    def __post_init__(self):
        check_positive(self, "duration_s", "motion_strength")
        for level, ms in self.blur_ms.items():
            if not ms > 0:
                raise ConfigError(f"blur_ms.{level}: expected a positive exposure in ms, got {ms!r}")

    @property
    def n_timestamps(self) -> int:
        """Rendered timestamps: the clip [0, duration] sampled at fps, both ends included."""
        return int(round(self.duration_s * self.render.fps)) + 1


@dataclass(frozen=True)
class PresetConfig:
    scenes: tuple[str, ...] = SCENE_NAMES
    overrides: dict[str, Any] = field(default_factory=dict)  # merged into every scene's YAML


def deep_merge(base: Mapping, override: Mapping) -> dict:
    out = copy.deepcopy(dict(base))
    for key, value in override.items():
        if isinstance(value, Mapping) and isinstance(out.get(key), Mapping):
            out[key] = deep_merge(out[key], value)
        else:
            out[key] = copy.deepcopy(value)
    return out


def _read_yaml(path: Path) -> dict:
    try:
        data = yaml.safe_load(path.read_text())
    except OSError as exc:
        raise ConfigError(f"{path}: cannot read ({exc.strerror})") from None
    except yaml.YAMLError as exc:
        raise ConfigError(f"{path}: not valid YAML: {exc}") from None
    if not isinstance(data, Mapping):
        raise ConfigError(f"{path}: expected a mapping at the top level")
    return dict(data)


def scene_yaml_path(name: str) -> Path:
    if name not in SCENE_NAMES and not (SCENES_DIR / f"{name}.yaml").exists():
        raise ConfigError(f"unknown scene {name!r}: expected one of {', '.join(SCENE_NAMES)}")
    return SCENES_DIR / f"{name}.yaml"


def load_preset(preset: str | Path) -> PresetConfig:
    path = Path(preset) if Path(preset).suffix in (".yaml", ".yml") else PRESETS_DIR / f"dataset_{preset}.yaml"
    if not path.exists():
        known = sorted(p.stem.removeprefix("dataset_") for p in PRESETS_DIR.glob("dataset_*.yaml"))
        raise ConfigError(f"unknown dataset preset {str(preset)!r} (no {path}); known presets: {', '.join(known)}")
    try:
        preset_cfg = from_dict(PresetConfig, _read_yaml(path))
    except ConfigError as exc:
        raise ConfigError(f"{path}: {exc}") from None
    for name in preset_cfg.scenes:
        scene_yaml_path(name)
    return preset_cfg


def resolve_scene(name: str, overrides: Mapping[str, Any] | None = None,
                  scene_file: str | Path | None = None) -> SceneConfig:
    """Scene YAML (or `scene_file`) with `overrides` merged in, parsed strictly."""
    path = Path(scene_file) if scene_file else scene_yaml_path(name)
    data = deep_merge(_read_yaml(path), overrides or {})
    try:
        cfg = from_dict(SceneConfig, data)
    except ConfigError as exc:
        raise ConfigError(f"{path}: {exc}") from None
    if scene_file is None and cfg.name != name:
        raise ConfigError(f"{path}: name: expected {name!r}, got {cfg.name!r}")
    return cfg
