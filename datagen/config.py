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


from common.config import ConfigError, check_positive, from_dict, read_yaml_mapping
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
class ShakeConfig:
    """High-frequency camera egomotion (a hand-held or robot-mounted rig): each camera rotates about
    its own axes by a sum of `components` sinusoids per axis, with frequencies drawn log-uniformly in
    [min_hz, max_hz] (real time, Hz) and random phases, seeded per scene and camera.

    rms_deg is the RMS rotation about the pan and tilt axes; roll gets roll_scale times that.
    rms_deg: 0 turns shake off.
    """
    rms_deg: float = 0.0
    min_hz: float = 4.0
    max_hz: float = 25.0
    components: int = 3
    roll_scale: float = 0.5

    def __post_init__(self):
        check_positive(self, "min_hz", "max_hz", "components")
        if not 0 <= self.rms_deg <= 10:
            raise ConfigError(f"rms_deg: expected 0 to 10 degrees, got {self.rms_deg!r}")
        if not self.min_hz <= self.max_hz:
            raise ConfigError(f"max_hz: expected at least min_hz ({self.min_hz}), got {self.max_hz!r}")
        if not 0 <= self.roll_scale <= 2:
            raise ConfigError(f"roll_scale: expected 0 to 2, got {self.roll_scale!r}")


@dataclass(frozen=True)
class CameraRigConfig:
    """Cameras uniformly spaced in azimuth on a spiral around `target`, at constant height.

    Camera k starts at azimuth azimuth0_deg + 360 k / n_cameras and turns by sweep_deg over the clip;
    its distance from the vertical axis through the target goes from radius to radius + radius_change.
    `shake` adds high-frequency rotation about each camera's own axes on top of the look-at pose.
    """
    n_cameras: int = 6
    radius: float = 4.0
    height: float = 1.5
    target: tuple[float, float, float] = (0.0, 0.0, 0.0)
    azimuth0_deg: float = 0.0
    sweep_deg: float = 30.0
    radius_change: float = 0.0
    fov_x_deg: float = 50.0
    shake: ShakeConfig = field(default_factory=ShakeConfig)

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
class BlurConfig:
    """Motion-blur levels declared by what they do: level name -> target blur length in pixels.

    The blur length of a blurred frame is the median, over the pixels covered by geometry, of the
    length of the image path each visible surface point travels during the exposure (computed from
    the scene geometry and camera poses, `datagen.blur_geometry`). The generator picks, per level,
    the exposure (a whole number of rendered frames, at most max_exposure_ms and the clip) whose
    median over every camera and blurred frame is closest to the target; a level whose closest
    exposure misses the target by more than `tolerance` (relative) is an error, never a clamp.
    sample_stride_px: the blur length is measured on every n-th pixel in x and y.
    """
    target_px: dict[str, float] = field(default_factory=dict)
    tolerance: float = 0.15
    max_exposure_ms: float = 40.0
    sample_stride_px: int = 4

    def __post_init__(self):
        check_positive(self, "tolerance", "max_exposure_ms", "sample_stride_px")
        for level, px in self.target_px.items():
            if not px > 0:
                raise ConfigError(f"target_px.{level}: expected a positive blur length in pixels, got {px!r}")
        values = list(self.target_px.values())
        if len(set(values)) != len(values):
            raise ConfigError(f"target_px: two levels share a target ({self.target_px})")
        if not self.tolerance < 1:
            raise ConfigError(f"tolerance: expected a relative tolerance below 1, got {self.tolerance!r}")

    @property
    def levels(self) -> list[str]:
        """Level names from the weakest to the strongest blur."""
        return sorted(self.target_px, key=self.target_px.get)


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
    blur: BlurConfig = field(default_factory=BlurConfig)  # no target_px: no blurred frames
    sensor: SimulatorConfig = field(default_factory=SimulatorConfig)

    def __post_init__(self):
        check_positive(self, "duration_s")
        if not self.motion_strength >= 0:   # 0: a static scene (only the cameras move)
            raise ConfigError(f"motion_strength: expected a value >= 0, got {self.motion_strength!r}")

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
        preset_cfg = from_dict(PresetConfig, read_yaml_mapping(path))
    except ConfigError as exc:
        raise ConfigError(f"{path}: {exc}") from None
    for name in preset_cfg.scenes:   # every scene must build with the preset's overrides: blame the right file
        try:
            resolve_scene(name, preset_cfg.overrides)
        except ConfigError as exc:
            resolve_scene(name)           # the scene's own YAML is wrong: that error, naming it
            detail = str(exc).split(": ", 1)[1] if ": " in str(exc) else str(exc)
            raise ConfigError(f"{path}: overrides (applied to scene {name!r}): {detail}") from None
    return preset_cfg


def resolve_scene(name: str, overrides: Mapping[str, Any] | None = None,
                  scene_file: str | Path | None = None) -> SceneConfig:
    """Scene YAML (or `scene_file`) with `overrides` merged in, parsed strictly."""
    path = Path(scene_file) if scene_file else scene_yaml_path(name)
    data = deep_merge(read_yaml_mapping(path), overrides or {})
    try:
        cfg = from_dict(SceneConfig, data)
    except ConfigError as exc:
        raise ConfigError(f"{path}: {exc}") from None
    if scene_file is None and cfg.name != name:
        raise ConfigError(f"{path}: name: expected {name!r}, got {cfg.name!r}")
    return cfg
