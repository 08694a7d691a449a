"""Benchmark presets: which scenes, which method cells, and the extra studies (blur, ablation).

A cell is a method (bundled, or a plug-in of the entry-point group `e4dgs.methods`) with a config
file, dotted overrides and a label; the same method appears in several cells (D3DGS on sharp and on
blurred frames). The preset's cells, in their YAML order, are the leaderboard's rows. Presets are
YAML files in configs/bench/ (`--preset quick` -> configs/bench/quick.yaml) loaded strictly.
"""
from __future__ import annotations

from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Any

from common.config import ConfigError, build_config, to_dict
from common.deprecations import BENCH_PRESETS, kept_until

REPO = Path(__file__).resolve().parent.parent
PRESET_DIR = REPO / "configs" / "bench"
SPREAD_METRICS = ("psnr", "ssim", "lpips", "psnr_luma", "psnr_dyn", "ssim_dyn", "lpips_dyn")   # benchmark.ties


@dataclass(frozen=True)
class CellSpec:
    """One row of the leaderboard: a registered method (bundled or a plug-in), its config and label."""
    method: str
    label: str = ""                                    # the tables' name for it ("": the cell's name)
    config: str = ""        # a training recipe: its name (`e4dgs/quick`) or a YAML path (relative to the repository root)
    overrides: dict[str, Any] = field(default_factory=dict)   # dotted keys, as `--set`
    speed: str = ""     # a speed level of the preset (speed_levels): train on that speed variant; "": the scene


@dataclass(frozen=True)
class BlurStudy:
    """The cells at every blur level on one scene. With the preset's speed_levels a level is a speed
    (every cell, events-only ones included, trains on that speed variant); without them a level is
    one of the scene's exposure levels, set through the config field its method names
    (Method.blur_level_field), and events-only methods are not re-run."""
    scene: str = ""                       # "" : no blur study
    levels: tuple[str, ...] = ("mild", "medium", "strong")  # the blur levels the study trains at
    cells: tuple[str, ...] = ("d3dgs_blur", "deblur_d3dgs", "e2vid_d3dgs", "e4dgs", "e4dgs_rgb")  # the cells the study trains


@dataclass(frozen=True)
class SpeedStudy:
    """Every cell at every speed factor on each scene (`e4dgs bench --studies speed`): the speed
    variants <scene>_x<s> of the dataset. d3dgs_sharp (the main cell: the sharp frames are the same at
    every speed) is the reference line. `sensor_scene` is also run with the speed variants of a
    realistic sensor (`sensor_dataset`, a dataset preset whose scene declares one)."""
    scenes: tuple[str, ...] = ()          # () : no speed study
    speeds: tuple[float, ...] = ()  # the speed factors swept (speed variants of the dataset)
    cells: tuple[str, ...] = ("d3dgs_blur", "deblur_d3dgs", "e2vid_d3dgs", "e4dgs", "e4dgs_rgb")  # the cells the study trains
    sensor_dataset: str = ""              # "" : no realistic-sensor run
    sensor_scene: str = ""                # the scene run on it ("": the first of `scenes`)
    sensor_cells: tuple[str, ...] = ("e2vid_d3dgs", "e4dgs", "e4dgs_rgb")  # the cells swept on sensor_dataset
    lpips: bool = False                   # its tables read PSNR: its own runs skip LPIPS unless asked
    reference: str = "d3dgs_sharp"        # the cell drawn as the reference line (trained at speed 1)
    rgb_reference: str = "d3dgs_blur"     # the RGB cell the event cells must overtake (crossing speeds)

    def __post_init__(self):
        if self.sensor_scene and self.sensor_scene not in self.scenes:
            raise ConfigError(f"sensor_scene: {self.sensor_scene!r} is not one of speed.scenes")
        if self.scenes and not self.speeds:
            raise ConfigError("speeds: expected the speed factors of the study")
        if any(not s >= 1 for s in self.speeds) or len(set(self.speeds)) != len(self.speeds):
            raise ConfigError(f"speeds: expected distinct speed factors >= 1, got {list(self.speeds)!r}")


@dataclass(frozen=True)
class AblationStudy:
    scene: str = ""                       # "" : no ablation
    base: str = "e4dgs"  # the cell the ablation switches parts of
    switches: dict[str, dict[str, Any]] = field(default_factory=lambda: {  # variant name -> the overrides it switches
        "w/o TV": {"events.lambda_tv": 0.0}, "w/o ESS": {"events.ess": False},
        "w/o AES": {"events.aes": False}, "w/o IIP": {"events.iip": False}})
    # training seeds (train.seed) of every variant and of the full method; the table gives their mean
    # and spread. Seed 0 is the configs' default, so the full method's seed-0 run is the main cell's.
    seeds: tuple[int, ...] = (0,)

    def __post_init__(self):
        if not self.seeds or len(set(self.seeds)) != len(self.seeds) or min(self.seeds) < 0:
            raise ConfigError(f"seeds: expected distinct seeds >= 0, got {list(self.seeds)!r}")


@dataclass(frozen=True)
class BenchConfig:
    dataset: str = "quick"               # data/<dataset>, generated with `e4dgs dataset --preset <dataset>`
    scenes: tuple[str, ...] = ("lego",)  # the dataset's scenes the leaderboard covers
    cells: dict[str, CellSpec] = field(default_factory=dict)  # the leaderboard's rows: {cell: {method, config, label, overrides, speed}}
    blur: BlurStudy = field(default_factory=BlurStudy)  # the blur study (off without a scene)
    ablation: AblationStudy = field(default_factory=AblationStudy)  # the E-4DGS ablation (off without a scene)
    speed: SpeedStudy = field(default_factory=SpeedStudy)  # the speed study (off without scenes)
    # blur levels as motion speeds (factors of the dataset's speed variants): {mild: s1, medium: s2, ...}
    speed_levels: dict[str, float] = field(default_factory=dict)
    # per-scene changes to a cell, on top of its overrides and under a study's own, e.g. the budget that
    # gives every cell the same training seconds on a slower scene: {scene: {cell: {dotted key: value}}}
    scene_overrides: dict[str, dict[str, dict[str, Any]]] = field(default_factory=dict)
    lpips_net: str = "vgg"  # LPIPS's network: vgg or alex
    # seeds of every main cell (0 .. seeds-1; `e4dgs bench --seeds N`): the tables give the mean and
    # spread over them, and call differences within the spread ties
    seeds: int = 1
    # what a seed varies (`e4dgs bench --seed-axes`): `train` (train.seed: the order of views and
    # windows, every random draw of training), `init` (train.init.seed: the initial points) and
    # `noise` (the dataset: seed k trains on data/<dataset>@noise<k>, the same scenes with the event
    # sensor's noise and mismatch seeded by k, generated when missing); the leaderboard's note names them
    seed_axes: tuple[str, ...] = ("train", "init")
    # the event sensor of the main table's event cells (`e4dgs bench --sensor davis346`): "" keeps each
    # scene's own; a name in configs/sensors/ trains them on data/<dataset>@<sensor> (the same scenes
    # seen by that sensor, generated when missing); cells that see no events keep the dataset's frames
    sensor: str = ""
    # the seed spread (standard deviation over training seeds) of each cell's scores on one scene, as
    # measured (docs/results/benchmark.md): what the tables take as a one-seed cell's spread where results.jsonl
    # holds no cell of its kind at two seeds or more: {cell: {psnr: dB, ssim: ..., lpips: ...}}
    seed_spread: dict[str, dict[str, float]] = field(default_factory=dict)
    snapshot_metrics: tuple[str, ...] = ("psnr", "ssim")    # at 10/25/50 % (the final model gets all)
    description: str = ""  # what the preset measures (printed above its tables)

    def __post_init__(self):
        if not self.cells:
            raise ConfigError("cells: expected at least one cell ({name: {method: ..., config: ..., label: ...}})")
        bad = [a for a in self.seed_axes if a not in SEED_AXES]
        if not self.seed_axes or bad or len(set(self.seed_axes)) != len(self.seed_axes):
            raise ConfigError(f"seed_axes: expected distinct names among {', '.join(SEED_AXES)}, got {list(self.seed_axes)!r}")
        for c in self.blur.cells if self.blur.scene else ():      # a study's cells matter when it runs
            if c not in self.cells:
                raise ConfigError(f"blur.cells: {c!r} is not a cell")
        sp = self.speed
        for c in (sp.cells + (sp.sensor_cells if sp.sensor_dataset else ())) if sp.scenes else ():
            if c not in self.cells:
                raise ConfigError(f"speed.cells: {c!r} is not a cell")
        if self.speed.scenes:
            for key in ("reference", "rgb_reference"):
                c = getattr(self.speed, key)
                if c not in self.cells:
                    raise ConfigError(f"speed.{key}: {c!r} is not a cell ({', '.join(self.cells)})")
        if self.sensor:
            from simulator.sensor_presets import read_sensor

            try:
                read_sensor(self.sensor)
            except ConfigError as exc:
                raise ConfigError(f"sensor: {exc}") from None
        for level, factor in self.speed_levels.items():
            if not factor >= 1:
                raise ConfigError(f"speed_levels.{level}: expected a speed factor >= 1, got {factor!r}")
        for name, c in self.cells.items():
            if c.speed and c.speed not in self.speed_levels:
                raise ConfigError(f"cells.{name}.speed: {c.speed!r} is not one of speed_levels "
                                  f"({', '.join(self.speed_levels) or 'none declared'})")
        if self.speed_levels and self.blur.scene:
            for level in self.blur.levels:
                if level not in self.speed_levels:
                    raise ConfigError(f"blur.levels: {level!r} is not one of speed_levels ({', '.join(self.speed_levels)})")
        if self.ablation.scene and self.ablation.base not in self.cells:
            raise ConfigError(f"ablation.base: {self.ablation.base!r} is not a cell")
        for cell, spread in self.seed_spread.items():
            if cell not in self.cells:
                raise ConfigError(f"seed_spread: {cell!r} is not a cell")
            for metric, value in spread.items():
                if metric not in SPREAD_METRICS or not 0 <= value < 100:
                    raise ConfigError(f"seed_spread.{cell}.{metric}: expected one of {', '.join(SPREAD_METRICS)} "
                                      f"with a standard deviation >= 0, got {value!r}")
        for scene, per_cell in self.scene_overrides.items():
            if scene not in self.scenes:
                raise ConfigError(f"scene_overrides: {scene!r} is not one of the scenes ({', '.join(self.scenes)})")
            for c in per_cell:
                if c not in self.cells:
                    raise ConfigError(f"scene_overrides.{scene}: {c!r} is not a cell")

    def overrides(self, scene: str, cell: str) -> dict[str, Any]:
        """A cell's overrides on one scene: the cell's own, then the scene's changes to it."""
        return {**self.cells[cell].overrides, **self.scene_overrides.get(scene, {}).get(cell, {})}

    def label(self, cell: str) -> str:
        return self.cells[cell].label or cell

    def labels(self) -> dict[str, str]:
        """cell -> label, in the preset's order (the leaderboard's rows)."""
        return {c: self.label(c) for c in self.cells}

    def cell_speed(self, cell: str) -> float | None:
        """The speed factor a cell trains at (None: the scene itself)."""
        level = self.cells[cell].speed
        return float(self.speed_levels[level]) if level else None


# Bench presets renamed in 0.2: old name -> (preset, overrides of every cell) (common.deprecations).
RENAMED_PRESETS = BENCH_PRESETS


def load_bench(preset: str | Path, overrides: dict[str, Any] | None = None) -> BenchConfig:
    """A bench preset (a name in configs/bench/ or a YAML file), with `overrides` (dotted keys, as
    `e4dgs bench --set`) applied to every cell after the cell's own."""
    import warnings

    from common.config_files import DeprecatedName, find, shipped_names

    if str(preset) in RENAMED_PRESETS:
        new, extra = RENAMED_PRESETS[str(preset)]
        sets = " ".join(f"--set {k}={v}" for k, v in extra.items())
        warnings.warn(f"bench preset {preset!r} is an old name (kept until {kept_until('bench preset', str(preset))}): "
                      f"use `--preset {new} {sets}`",
                      DeprecatedName, stacklevel=2)
        preset, overrides = new, {**extra, **(overrides or {})}
    path = find("bench", preset)
    if path is None:
        where = Path(preset) if Path(preset).suffix else PRESET_DIR / f"{preset}.yaml"
        raise ConfigError(f"{where}: no such benchmark preset (known: {', '.join(shipped_names('bench'))})")
    cfg = build_config(BenchConfig, path)
    if overrides:
        cfg = replace(cfg, cells={name: replace(c, overrides={**c.overrides, **overrides}) for name, c in cfg.cells.items()})
    return cfg


def dump(cfg: BenchConfig) -> dict:
    return to_dict(cfg)


BenchConfig.BOUNDS = {"seeds": (1, 100, "training seeds per cell")}
# axis -> the config field a seed sets (noise: none; the seed picks the dataset's noise realisation)
SEED_AXES = {"train": "train.seed", "init": "train.init.seed", "noise": None}
