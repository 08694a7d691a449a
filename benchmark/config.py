"""Benchmark presets: which scenes, which method cells, and the extra studies (blur, ablation).

A cell is a method (bundled, or a plug-in of the entry-point group `e4dgs.methods`) with a config
file, dotted overrides and a label; the same method appears in several cells (D3DGS on sharp and on
blurred frames). The preset's cells, in their YAML order, are the leaderboard's rows. Presets are
YAML files in configs/bench/ (`--preset quick` -> configs/bench/quick.yaml) loaded strictly.
"""
from __future__ import annotations

import functools
import hashlib
import json
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Any

from common.config import ConfigError, build_config, to_dict

REPO = Path(__file__).resolve().parent.parent
PRESET_DIR = REPO / "configs" / "bench"
SPREAD_METRICS = ("psnr", "ssim", "lpips", "psnr_luma", "psnr_dyn", "ssim_dyn", "lpips_dyn")   # benchmark.ties


@dataclass(frozen=True)
class CellSpec:
    """One row of the leaderboard: a registered method (bundled or a plug-in), its config and label."""
    method: str
    label: str = ""                                    # the tables' name for it ("": the cell's name)
    config: str = ""                                   # recon config YAML, relative to the repository root
    overrides: dict[str, Any] = field(default_factory=dict)   # dotted keys, as `--set`
    speed: str = ""     # a speed level of the preset (speed_levels): train on that speed variant; "": the scene


@dataclass(frozen=True)
class BlurStudy:
    """The cells at every blur level on one scene. With the preset's speed_levels a level is a speed
    (every cell, events-only ones included, trains on that speed variant); without them a level is
    one of the scene's exposure levels, set through the config field its method names
    (Method.blur_level_field), and events-only methods are not re-run."""
    scene: str = ""                       # "" : no blur study
    levels: tuple[str, ...] = ("mild", "medium", "strong")
    cells: tuple[str, ...] = ("d3dgs_blur", "deblur_d3dgs", "e2vid_d3dgs", "e4dgs", "e4dgs_rgb")


@dataclass(frozen=True)
class SpeedStudy:
    """Every cell at every speed factor on each scene (`e4dgs bench --studies speed`): the speed
    variants <scene>_x<s> of the dataset. d3dgs_sharp (the main cell: the sharp frames are the same at
    every speed) is the reference line. `sensor_scene` is also run with the speed variants of a
    realistic sensor (`sensor_dataset`, a dataset preset whose scene declares one)."""
    scenes: tuple[str, ...] = ()          # () : no speed study
    speeds: tuple[float, ...] = ()
    cells: tuple[str, ...] = ("d3dgs_blur", "deblur_d3dgs", "e2vid_d3dgs", "e4dgs", "e4dgs_rgb")
    sensor_dataset: str = ""              # "" : no realistic-sensor run
    sensor_scene: str = ""                # the scene run on it ("": the first of `scenes`)
    sensor_cells: tuple[str, ...] = ("e2vid_d3dgs", "e4dgs", "e4dgs_rgb")
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
    base: str = "e4dgs"
    switches: dict[str, dict[str, Any]] = field(default_factory=lambda: {
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
    scenes: tuple[str, ...] = ("lego",)
    cells: dict[str, CellSpec] = field(default_factory=dict)
    blur: BlurStudy = field(default_factory=BlurStudy)
    ablation: AblationStudy = field(default_factory=AblationStudy)
    speed: SpeedStudy = field(default_factory=SpeedStudy)
    # blur levels as motion speeds (factors of the dataset's speed variants): {mild: s1, medium: s2, ...}
    speed_levels: dict[str, float] = field(default_factory=dict)
    # per-scene changes to a cell, on top of its overrides and under a study's own, e.g. the budget that
    # gives every cell the same training seconds on a slower scene: {scene: {cell: {dotted key: value}}}
    scene_overrides: dict[str, dict[str, dict[str, Any]]] = field(default_factory=dict)
    lpips_net: str = "vgg"
    # training seeds of every main cell (train.seed 0 .. seeds-1; `e4dgs bench --seeds N`): the tables
    # give the mean and spread over them, and call differences within the spread ties
    seeds: int = 1
    # the seed spread (standard deviation over training seeds) of each cell's scores on one scene, as
    # measured (docs/benchmark.md): what the tables take as a one-seed cell's spread where results.jsonl
    # holds no cell of its kind at two seeds or more: {cell: {psnr: dB, ssim: ..., lpips: ...}}
    seed_spread: dict[str, dict[str, float]] = field(default_factory=dict)
    snapshot_metrics: tuple[str, ...] = ("psnr", "ssim")    # at 10/25/50 % (the final model gets all)
    description: str = ""

    def __post_init__(self):
        if not self.cells:
            raise ConfigError("cells: expected at least one cell ({name: {method: ..., config: ..., label: ...}})")
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
    speed: float | None = None    # train on the scene's speed variant <scene>_x<speed> (None: the scene)
    dataset: str = ""             # another dataset preset's folder (the realistic-sensor variants); "": the preset's
    label: str = ""               # the cell's label in the tables
    inputs: tuple[str, ...] = ()  # what its method sees (Method.inputs): the tables read it from the row
    data_root: str = ""           # the dataset folder its scene is read from (data/<dataset>)

    @property
    def data_scene(self) -> str:
        """The scene folder it trains on: the scene, or its speed variant."""
        from scene_format.naming import variant_name

        return variant_name(self.scene, self.speed) if self.speed is not None else self.scene

    @property
    def key(self) -> str:
        seed = f"seed{self.seed}" if self.seed is not None else ""
        return "/".join(p for p in (self.study, self.dataset, self.scene, self.cell, self.variant, seed) if p)

    @functools.cached_property
    def folder(self) -> str:
        """Its training folder under the results root, '<scene>/<method>-<config hash>' (shared by jobs
        that train the same thing)."""
        prefix = f"{self.dataset}/" if self.dataset else ""
        return f"{prefix}{self.data_scene}/{self.method}-{self.config_hash()}"

    def identity(self) -> dict[str, Any]:
        """The fields of its results row that say which job it is."""
        return {"key": self.key, "study": self.study, "scene": self.scene, "cell": self.cell, "variant": self.variant,
                "seed": self.seed, "method": self.method, "config": self.config, "overrides": self.overrides,
                "speed": self.speed, "data_scene": self.data_scene, "dataset": self.dataset,
                "config_hash": self.config_hash(), "run_dir": self.folder, "label": self.label or self.cell,
                "inputs": list(self.inputs), "identity": dict(self.identity_parts),
                "code_version": self.identity_parts["code"]}

    @functools.cached_property
    def method_config(self):
        """The typed config it trains with: its config file, then its overrides, resolved once per job
        (every field, after defaults, as the trainer sees it). ConfigError names the job."""
        try:
            return _resolved(self.method, self.config, json.dumps(self.overrides, sort_keys=True, default=str),
                             _file_stamp(REPO / self.config) if self.config else None)
        except (ConfigError, ValueError) as exc:
            raise ConfigError(f"bench job {self.key} ({self.method}, {self.config or 'defaults'}): {exc}") from None

    def _input_digests(self) -> dict[str, str]:
        """The method's `input_digests` under this job's config (E2VID + D3DGS: its network's weights)."""
        from recon.methods import get_method

        return get_method(self.method).input_digests(self.method_config)

    @property
    def data_dir(self) -> Path:
        """The scene folder it trains on: <data root>/<scene or speed variant>, or that folder in the
        sibling dataset job.dataset."""
        root = Path(self.data_root) if self.data_root else Path("data") / "?"
        return (root.parent / self.dataset if self.dataset else root) / self.data_scene

    @functools.cached_property
    def identity_parts(self) -> dict[str, str]:
        """What makes its result, each as a digest: `config` (the method and its resolved config, every
        field), `inputs` (files the method reads besides config and scene: E2VID's weights), `dataset`
        (the scene folder's content, scene_format.manifest.content_digest, with its name) and `code`
        (common.provenance.code_version, plus a plug-in method's own source file). A row whose parts
        differ from its job's was made by something else."""
        from common.config import dump_config
        from common.provenance import code_version
        from recon.methods import get_method
        from scene_format.manifest import folder_digest

        code = code_version()
        source = _source_file(get_method(self.method))
        if source is not None and not source.is_relative_to(REPO):      # a plug-in's code is its own file
            code = _sha({"toolkit": code, "plugin": hashlib.sha256(source.read_bytes()).hexdigest()})
        return {"config": _sha({"method": self.method, "config": dump_config(self.method_config)}),
                "inputs": _sha(self._input_digests()),
                "dataset": _sha({"scene": self.data_scene, "dataset": self.dataset,
                                 "content": folder_digest(self.data_dir)}),
                "code": code}

    def config_hash(self) -> str:
        """The digest of everything that makes its result (identity_parts), computed once per job: the
        job's identity, and the name of its training folder."""
        return self._config_hash

    @functools.cached_property
    def _config_hash(self) -> str:
        return _sha(self.identity_parts)


@functools.lru_cache(maxsize=4096)
def _resolved(method: str, config: str, overrides_json: str, stamp):
    """A method's config file plus overrides, resolved once per process for each distinct (method,
    file as it is on disk, overrides): the jobs of a bench, and the grid its tables are checked
    against, share one resolution (the file read once per distinct job)."""
    from recon.api import resolve_config

    return resolve_config(method, str(REPO / config) if config else None, json.loads(overrides_json),
                          "the preset's overrides of this job (cells, studies, scene_overrides)")


def _file_stamp(path: Path):
    """(mtime_ns, size) of a file, None where it is missing: a file edited in place resolves again."""
    try:
        st = path.stat()
    except OSError:
        return None
    return st.st_mtime_ns, st.st_size


def _sha(obj: Any) -> str:
    return hashlib.sha256(json.dumps(obj, sort_keys=True, default=str).encode()).hexdigest()[:16]


def _source_file(cls: type) -> Path | None:
    """The resolved source file defining `cls` (None where it has none)."""
    import inspect

    try:
        path = inspect.getsourcefile(cls)
    except TypeError:
        return None
    return Path(path).resolve() if path and Path(path).is_file() else None


def _at_speed(cfg: BenchConfig, scene: str, cell: str, speed: float | None) -> dict[str, Any]:
    """A cell's overrides on a scene, trained at `speed`: a method that sees blurred RGB takes the speed
    variant's blurred frames (its blur-level field set to the variant's `shutter` level)."""
    from scene_format.naming import SHUTTER_LEVEL
    from recon.methods import get_method

    key = get_method(cfg.cells[cell].method).blur_level_field
    extra = {key: SHUTTER_LEVEL} if speed is not None and key is not None else {}
    return {**cfg.overrides(scene, cell), **extra}


def _described(cfg: BenchConfig, job: Job) -> Job:
    """The job with its cell's label and its method's inputs (what the tables read from its row)."""
    from dataclasses import replace

    from recon.methods import get_method

    return replace(job, label=cfg.label(job.cell), inputs=tuple(get_method(job.method).inputs))


def jobs(cfg: BenchConfig, data_root: Path | None = None) -> list[Job]:
    """Every training run of a preset, main table first (each cell at each of `cfg.seeds` seeds);
    studies reuse main runs where they coincide. `data_root`: the dataset folder (default
    data/<dataset>), whose scene folders' digests are part of each job's identity. ConfigError names a
    cell whose method is not registered (bundled or plug-in)."""
    from recon.methods import get_method

    for name, c in cfg.cells.items():
        try:
            get_method(c.method)
        except ValueError as exc:
            raise ConfigError(f"cells.{name}.method: {exc}") from None
    root = str(data_root if data_root is not None else Path("data") / cfg.dataset)
    return [replace(_described(cfg, j), data_root=root) for j in _jobs(cfg)]


def _jobs(cfg: BenchConfig) -> list[Job]:
    out: list[Job] = []
    for seed in range(cfg.seeds):      # seed 0 (the configs' default) keeps the plain key
        for scene in cfg.scenes:
            for name, c in cfg.cells.items():
                seeded = {"train.seed": seed} if seed else {}
                out.append(Job("main", scene, name, "", c.method, c.config,
                               {**_at_speed(cfg, scene, name, cfg.cell_speed(name)), **seeded},
                               seed=seed or None, speed=cfg.cell_speed(name)))
    b = cfg.blur
    if b.scene:
        from recon.methods import get_method

        for name in b.cells:
            c = cfg.cells[name]
            key = get_method(c.method).blur_level_field
            for level in b.levels:
                if cfg.speed_levels:        # a level is a speed: every cell, on that variant's frames and events
                    speed = float(cfg.speed_levels[level])
                    out.append(Job("blur", b.scene, name, level, c.method, c.config,
                                   _at_speed(cfg, b.scene, name, speed), speed=speed))
                elif key is not None:       # an exposure level: events-only methods never see it
                    out.append(Job("blur", b.scene, name, level, c.method, c.config,
                                   {**cfg.overrides(b.scene, name), key: level}))
    sp = cfg.speed
    sweeps = [(scene, sp.cells, "") for scene in sp.scenes]
    if sp.sensor_dataset:                 # the same sweep on the realistic sensor's dataset
        sweeps.append((sp.sensor_scene or sp.scenes[0], sp.sensor_cells, sp.sensor_dataset))
    for scene, cells, dataset in sweeps:
        if not dataset:                   # the reference line: the main cell's run, the same at every speed
            ref = cfg.cells[sp.reference]
            out.append(Job("speed", scene, sp.reference, "sharp", ref.method, ref.config,
                           _at_speed(cfg, scene, sp.reference, None)))
        for name in cells:
            c = cfg.cells[name]
            for s in sp.speeds:
                out.append(Job("speed", scene, name, f"x{s:g}", c.method, c.config, _at_speed(cfg, scene, name, s),
                               speed=float(s), dataset=dataset))
    a = cfg.ablation
    if a.scene:
        c = cfg.cells[a.base]
        for seed in a.seeds:
            seeded = {"train.seed": seed} if seed != 0 else {}
            for variant, switch in [("full", {})] + list(a.switches.items()):
                out.append(Job("ablation", a.scene, a.base, variant, c.method, c.config,
                               {**cfg.overrides(a.scene, a.base), **switch, **seeded}, seed))
    return out


def current_rows(cfg: BenchConfig, rows: list[dict], data_root: Path | None = None,
                 reuse_older: bool = False) -> tuple[list[dict], list[dict]]:
    """(rows of the preset as it is now, stale rows). A bench row is current when a job of the preset has
    its key and identity (config_hash: resolved config, inputs, dataset, code). Other rows stay in
    results.jsonl but out of the tables, which must not mix what made them: another recipe, cap or speed
    list, another dataset or code version. With `reuse_older`, a row of a current job's key made by
    another code version or dataset (the same resolved config and inputs; rows from before identities
    were recorded: their config unknown) is kept, marked with `older` (what differs, for the tables).
    Rows scored from outside (`e4dgs score`) are always kept, and main and ablation rows are matched at
    their own seed (the seeds are chosen per run). The kept rows come in the preset's scene order
    (stably), so the tables' columns do not follow which scene was re-run last."""
    seeds = tuple(sorted({*cfg.ablation.seeds, *(r["seed"] for r in rows if r.get("study") == "ablation"
                                                  and isinstance(r.get("seed"), int))}))
    main_seeds = max([cfg.seeds] + [r["seed"] + 1 for r in rows if r.get("study") == "main"
                                    and isinstance(r.get("seed"), int)])
    grid = jobs(replace(cfg, seeds=main_seeds, ablation=replace(cfg.ablation, seeds=seeds)), data_root)
    by_key = {j.key: j for j in grid}
    kept, stale = [], []
    for r in rows:
        job = by_key.get(r.get("key"))
        note = None if r.get("external") or job is None else older_note(r, job)
        if r.get("external") or (job is not None and note is None):
            kept.append(r)
        elif note and reuse_older and note != "config":
            kept.append({**r, "older": note})
        else:
            stale.append(r)
    order = {s: i for i, s in enumerate(cfg.scenes)}
    kept.sort(key=lambda r: order.get(r.get("scene"), len(order)))
    return kept, stale


def older_note(row: dict, job: Job) -> str | None:
    """None when `row` was made by `job` as it is now; else what made it differ: "config" (another
    resolved config or input file: never reused), or a note for the tables naming the code version and
    dataset it came from ("code 1a2b3c4d, dataset ..."; the row's git_commit says which checkout, and
    one code version spans many commits) or "unknown version (git 5e6f7a8)" for a row from before
    identities were recorded."""
    try:
        if row.get("config_hash") == job.config_hash():
            return None
        now = job.identity_parts
    except ConfigError:                    # the preset's recipe no longer resolves: the row is stale
        return "config"
    then = row.get("identity")
    git = f" (git {row['git_commit'][:7]})" if row.get("git_commit") else ""
    if not isinstance(then, dict):
        return f"unknown version{git}"
    if then.get("config") != now["config"] or then.get("inputs") != now["inputs"]:
        return "config"
    parts = [f"code {then.get('code', '?')[:8]}" if then.get("code") != now["code"] else "",
             f"dataset {then.get('dataset', '?')[:8]}" if then.get("dataset") != now["dataset"] else ""]
    return ", ".join(p for p in parts if p) or "unknown version"


def dump(cfg: BenchConfig) -> dict:
    return to_dict(cfg)


BenchConfig.BOUNDS = {"seeds": (1, 100, "training seeds per cell")}
