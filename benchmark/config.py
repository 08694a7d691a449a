"""Benchmark presets: which scenes, which method cells, and the extra studies (blur, ablation).

A cell is a method with a config file and dotted overrides; the same method appears in several
cells (D3DGS on sharp and on blurred frames; E-4DGS with a component switched off). Presets are
YAML files in configs/bench/ (`--preset quick` -> configs/bench/quick.yaml) loaded strictly.
"""
from __future__ import annotations

import hashlib
import json
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from common.config import ConfigError, build_config, to_dict

REPO = Path(__file__).resolve().parent.parent
PRESET_DIR = REPO / "configs" / "bench"

# the leaderboard's rows, in the paper's Table 1 order
MAIN_CELLS = ("d3dgs_sharp", "d3dgs_blur", "deblur_d3dgs", "e2vid_d3dgs", "e4dgs", "e4dgs_rgb")
LABELS = {"d3dgs_sharp": "D3DGS (sharp RGB)", "d3dgs_blur": "D3DGS (blurred RGB)",
          "deblur_d3dgs": "Deblur-D3DGS (Deblur4DGS blur model, blurred RGB)", "e2vid_d3dgs": "E2VID + D3DGS",
          "e4dgs": "E-4DGS (events)", "e4dgs_rgb": "E-4DGS (events + blurred RGB)"}


@dataclass(frozen=True)
class CellSpec:
    method: str
    config: str = ""                                   # recon config YAML, relative to the repository root
    overrides: dict[str, Any] = field(default_factory=dict)   # dotted keys, as `--set`


@dataclass(frozen=True)
class BlurStudy:
    scene: str = ""                       # "" : no blur study
    levels: tuple[str, ...] = ("mild", "medium", "strong")
    cells: tuple[str, ...] = ("d3dgs_blur", "deblur_d3dgs", "e2vid_d3dgs", "e4dgs", "e4dgs_rgb")
    # each level is set through the config field its method names (Method.blur_level_field)


@dataclass(frozen=True)
class AblationStudy:
    scene: str = ""                       # "" : no ablation
    base: str = "e4dgs"
    switches: dict[str, dict[str, Any]] = field(default_factory=lambda: {
        "w/o TV": {"events.lambda_tv": 0.0}, "w/o ESS": {"events.ess": False},
        "w/o AES": {"events.aes": False}, "w/o IIP": {"events.iip": False}})
    # training seeds (train.seed) of every variant and of the full method; the table gives their mean
    # and spread. Seed 0 is the configs' default, so the full method's seed-0 run is the main cell's.
    seeds: tuple[int, ...] = (0,)

    def __post_init__(self):
        if not self.seeds or len(set(self.seeds)) != len(self.seeds) or min(self.seeds) < 0:
            raise ConfigError(f"ablation.seeds: expected distinct seeds >= 0, got {list(self.seeds)!r}")


@dataclass(frozen=True)
class BenchConfig:
    dataset: str = "quick"               # data/<dataset>, generated with `e4dgs dataset --preset <dataset>`
    scenes: tuple[str, ...] = ("lego",)
    cells: dict[str, CellSpec] = field(default_factory=dict)
    blur: BlurStudy = field(default_factory=BlurStudy)
    ablation: AblationStudy = field(default_factory=AblationStudy)
    # per-scene changes to a cell, on top of its overrides and under a study's own, e.g. the budget that
    # gives every cell the same training seconds on a slower scene: {scene: {cell: {dotted key: value}}}
    scene_overrides: dict[str, dict[str, dict[str, Any]]] = field(default_factory=dict)
    lpips_net: str = "vgg"
    snapshot_metrics: tuple[str, ...] = ("psnr", "ssim")    # at 10/25/50 % (the final model gets all)
    description: str = ""

    def __post_init__(self):
        unknown = [c for c in MAIN_CELLS if c not in self.cells]
        if unknown:
            raise ConfigError(f"cells: missing {', '.join(unknown)} (every preset defines the six main cells)")
        for c in self.blur.cells:
            if c not in self.cells:
                raise ConfigError(f"blur.cells: {c!r} is not a cell")
        if self.ablation.scene and self.ablation.base not in self.cells:
            raise ConfigError(f"ablation.base: {self.ablation.base!r} is not a cell")
        for scene, per_cell in self.scene_overrides.items():
            if scene not in self.scenes:
                raise ConfigError(f"scene_overrides: {scene!r} is not one of the scenes ({', '.join(self.scenes)})")
            for c in per_cell:
                if c not in self.cells:
                    raise ConfigError(f"scene_overrides.{scene}: {c!r} is not a cell")

    def overrides(self, scene: str, cell: str) -> dict[str, Any]:
        """A cell's overrides on one scene: the cell's own, then the scene's changes to it."""
        return {**self.cells[cell].overrides, **self.scene_overrides.get(scene, {}).get(cell, {})}


def load_bench(preset: str | Path) -> BenchConfig:
    path = Path(preset)
    if not path.suffix:
        path = PRESET_DIR / f"{preset}.yaml"
    if not path.exists():
        known = sorted(p.stem for p in PRESET_DIR.glob("*.yaml"))
        raise ConfigError(f"{path}: no such benchmark preset (known: {', '.join(known)})")
    return build_config(BenchConfig, path)


@dataclass(frozen=True)
class Job:
    """One training run: a cell (possibly varied for a study) on one scene."""
    study: str            # main | blur | ablation
    scene: str
    cell: str             # the main cell it derives from
    variant: str          # "" (main), a blur level, or an ablation name
    method: str
    config: str
    overrides: dict[str, Any]
    seed: int | None = None   # ablation runs: the training seed (part of the key)

    @property
    def key(self) -> str:
        seed = f"seed{self.seed}" if self.seed is not None else ""
        return "/".join(p for p in (self.study, self.scene, self.cell, self.variant, seed) if p)

    @property
    def folder(self) -> str:
        """Its training folder under the results root, '<scene>/<method>-<config hash>' (shared by jobs
        that train the same thing)."""
        return f"{self.scene}/{self.method}-{self.config_hash()}"

    def identity(self) -> dict[str, Any]:
        """The fields of its results row that say which job it is."""
        return {"key": self.key, "study": self.study, "scene": self.scene, "cell": self.cell, "variant": self.variant,
                "seed": self.seed, "method": self.method, "config": self.config, "overrides": self.overrides,
                "config_hash": self.config_hash(), "run_dir": self.folder}

    def config_hash(self) -> str:
        payload = {"method": self.method, "overrides": self.overrides,
                   "config": (REPO / self.config).read_text() if self.config else ""}
        if self.method == "e2vid_d3dgs":      # the network's weights are an input too
            from e2vid.weights import default_weights_path
            weights = self.overrides.get("weights") or default_weights_path()
            payload["weights_sha256"] = hashlib.sha256(Path(weights).read_bytes()).hexdigest()
        return hashlib.sha256(json.dumps(payload, sort_keys=True, default=str).encode()).hexdigest()[:16]


def jobs(cfg: BenchConfig) -> list[Job]:
    """Every training run of a preset, main table first; studies reuse main runs where they coincide."""
    out: list[Job] = []
    for scene in cfg.scenes:
        for name in MAIN_CELLS:
            c = cfg.cells[name]
            out.append(Job("main", scene, name, "", c.method, c.config, cfg.overrides(scene, name)))
    b = cfg.blur
    if b.scene:
        from recon.methods import get_method

        for name in b.cells:
            c = cfg.cells[name]
            key = get_method(c.method).blur_level_field
            for level in b.levels:
                if key is None:      # the method never sees RGB frames: blur cannot change it
                    continue
                out.append(Job("blur", b.scene, name, level, c.method, c.config,
                               {**cfg.overrides(b.scene, name), key: level}))
    a = cfg.ablation
    if a.scene:
        c = cfg.cells[a.base]
        for seed in a.seeds:
            seeded = {"train.seed": seed} if seed != 0 else {}
            for variant, switch in [("full", {})] + list(a.switches.items()):
                out.append(Job("ablation", a.scene, a.base, variant, c.method, c.config,
                               {**cfg.overrides(a.scene, a.base), **switch, **seeded}, seed))
    return out


def dump(cfg: BenchConfig) -> dict:
    return to_dict(cfg)
