"""A preset's grid: its training runs (`Job`: a cell, possibly varied for a study, on one scene, at
one seed) and what makes each one's result, its identity (resolved config, input files, the scene's
content, the code version), which decides whether a results row may stand for it (`current_rows`,
`older_note`). The presets themselves are benchmark.config."""
from __future__ import annotations

import functools
import hashlib
import json
from dataclasses import dataclass, replace
from pathlib import Path
from typing import Any

from benchmark.config import REPO, BenchConfig
from common.config import ConfigError


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
                             _file_stamp(_recipe_file(self.method, self.config)) if self.config else None)
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
        (the scene folder's content as it is on disk, scene_format.manifest.folder_digest, with its
        name), `code` (common.provenance.code_version of the job's driver and the method's module:
        every checkout module they import, normalised; a plug-in method outside the checkout adds its
        own file) and `placement` (the config's `auto` choices as this machine resolves them: device,
        backend, deformation precision). A row whose parts differ from its job's was made by
        something else."""
        from common.config import dump_config
        from scene_format.manifest import folder_digest

        return {"config": _sha({"method": self.method, "config": dump_config(self.method_config)}),
                "inputs": _sha(self._input_digests()),
                "dataset": _sha({"scene": self.data_scene, "dataset": self.dataset,
                                 "content": folder_digest(self.data_dir)}),
                "code": method_code_version(self.method),
                "placement": _sha(resolved_placement(self.method_config))}

    def config_hash(self) -> str:
        """The digest of everything that makes its result (identity_parts), computed once per job: the
        job's identity, and the name of its training folder."""
        return self._config_hash

    @functools.cached_property
    def _config_hash(self) -> str:
        return _sha(self.identity_parts)


@functools.lru_cache(maxsize=None)
def method_code_version(method: str) -> str:
    """The code version of a job of `method` (computed once per process): the import closure of the
    job's driver and the module that defines the method; a plug-in defined outside the checkout adds
    the normalised digest of its own source file."""
    from common.provenance import JOB_ENTRY, code_version, normalised_digest
    from recon.methods import get_method

    cls = get_method(method)
    source = _source_file(cls)
    if source is not None and not source.is_relative_to(REPO):      # a plug-in's code is its own file
        return _sha({"toolkit": code_version(REPO, (JOB_ENTRY,)), "plugin": normalised_digest(source)})
    return code_version(REPO, (JOB_ENTRY, cls.__module__))


def resolved_placement(method_cfg) -> dict[str, str]:
    """{device, backend, precision} that a run of `method_cfg` resolves to on this machine (its `auto`
    choices: recon.device.run_placement, recon.precision.resolve_precision, measured once per machine
    and cached); a plug-in without the shared TrainConfig: {}. A DeviceError is a ConfigError."""
    t = getattr(method_cfg, "train", None)
    if t is None:
        return {}
    return _placement(t.device, t.backend, t.precision, t.deform_field.kind, (t.deform_field.depth, t.deform_field.width))


@functools.lru_cache(maxsize=None)
def _placement(device: str, backend: str, precision: str, field_kind: str,
               size: tuple[int, int] = (8, 256)) -> dict[str, str]:
    from recon.device import DeviceError, run_placement
    from recon.precision import resolve_precision

    try:
        dev, back = run_placement(device, backend)
    except DeviceError as exc:
        raise ConfigError(str(exc)) from None
    return {"device": dev.type, "backend": back,          # as recon.trainer.Trainer resolves them
            "precision": resolve_precision(precision, dev, field_kind=field_kind, size=size).dtype}


@functools.lru_cache(maxsize=4096)
def _resolved(method: str, config: str, overrides_json: str, stamp):
    """A method's config file plus overrides, resolved once per process for each distinct (method,
    file as it is on disk, overrides): the jobs of a bench, and the grid its tables are checked
    against, share one resolution (the file read once per distinct job)."""
    from recon.api import resolve_config

    return resolve_config(method, _recipe_file(method, config) if config else None, json.loads(overrides_json),
                          "the preset's overrides of this job (cells, studies, scene_overrides)")


def _recipe_file(method: str, config: str) -> Path:
    """A cell's `config:` (a recipe name such as `e4dgs/quick`, or a path) as a file (recon.config_path)."""
    from recon.api import config_path

    return config_path(config if Path(config).is_absolute() or not (REPO / config).is_file() else REPO / config, method)


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


def seed_overrides(cfg: BenchConfig, seed: int) -> dict[str, int]:
    """The config fields seed `seed` sets: every field of the preset's seed_axes (benchmark.config.
    SEED_AXES); seed 0 sets none (the configs' defaults are 0)."""
    from benchmark.config import SEED_AXES

    return {SEED_AXES[a]: seed for a in cfg.seed_axes if SEED_AXES[a]} if seed else {}


def seed_dataset(cfg: BenchConfig, seed: int, method: str | None = None) -> str:
    """The dataset a main job of `seed` (and `method`) trains on: the preset's own (""), or, for a
    method that sees events under the preset's `sensor`, `<dataset>@<sensor>`, and with the `noise`
    seed axis the noise realisation `...@noise<seed>` (datagen.config.load_preset)."""
    name = cfg.dataset
    if cfg.sensor and method is not None:
        from recon.methods import get_method

        if "events" in get_method(method).inputs:
            name += f"@{cfg.sensor}"
    if seed and "noise" in cfg.seed_axes:
        name += f"@noise{seed}"
    return "" if name == cfg.dataset else name


def _jobs(cfg: BenchConfig) -> list[Job]:
    out: list[Job] = []
    for seed in range(cfg.seeds):      # seed 0 (the configs' default) keeps the plain key
        for scene in cfg.scenes:
            for name, c in cfg.cells.items():
                seeded = seed_overrides(cfg, seed)
                out.append(Job("main", scene, name, "", c.method, c.config,
                               {**_at_speed(cfg, scene, name, cfg.cell_speed(name)), **seeded},
                               seed=seed or None, speed=cfg.cell_speed(name),
                               dataset=seed_dataset(cfg, seed, c.method)))
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
            seeded = seed_overrides(cfg, seed)
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
        note = None if r.get("external") or job is None else older_note(r, job) or (
            None if r.get("status") == "failed" else scoring_note(r, job, cfg))      # a failed row has no scores
        if r.get("external") or (job is not None and note is None):
            kept.append(r)
        elif note and reuse_older and note != "config" and (r.get("status") == "failed"
                                                             or not scoring_note(r, job, cfg)):
            kept.append({**r, "older": note})
        else:
            stale.append(r)
    order = {s: i for i, s in enumerate(cfg.scenes)}
    kept.sort(key=lambda r: order.get(r.get("scene"), len(order)))
    return kept, stale


def wants_lpips(job: Job, cfg: BenchConfig) -> bool:
    """Whether a job's row needs LPIPS: the speed study reads PSNR only, so its own runs skip LPIPS-VGG
    (~30 s of a task) unless speed.lpips; a row without it is not reused for a job that needs it."""
    return not (job.study == "speed" and not cfg.speed.lpips)


def scoring_note(row: dict, job: Job, cfg: BenchConfig) -> str | None:
    """None when `row` was scored as `job` is scored now; else what differs: the LPIPS network (the
    preset's `lpips_net`, for a job that wants LPIPS) or the scene's dynamic masks (`e4dgs masks`
    again, another threshold). Scoring is not training: such a row is scored again from its trained
    model, never shown beside rows scored the other way."""
    from scene_format.manifest import masks_digest

    if wants_lpips(job, cfg) and row.get("lpips_net") != cfg.lpips_net:
        return f"LPIPS {row.get('lpips_net') or 'none'}, not {cfg.lpips_net}"
    if row.get("masks", "none") != masks_digest(job.data_dir):
        return "scored with other dynamic masks"
    return None


def older_note(row: dict, job: Job) -> str | None:
    """None when `row` was made by `job` as it is now; else what made it differ: "config" (another
    resolved config or input file: never reused), or a note for the tables naming the code version and
    dataset it came from ("code 1a2b3c4d, dataset ..."; the row's git_commit says which checkout, and
    one code version spans many commits). A row from before identities were recorded, or of another
    resolved placement (device, backend, precision), is "config": never reused."""
    try:
        if row.get("config_hash") == job.config_hash():
            return None
        now = job.identity_parts
    except ConfigError:                    # the preset's recipe no longer resolves: the row is stale
        return "config"
    then = row.get("identity")
    if not isinstance(then, dict):        # made before identities were recorded: its recipe is unknown
        return "config"
    # a row from before the placement was an identity part: what it recorded running on
    placement = then.get("placement") or _sha({k: row.get(k) for k in ("device", "backend", "precision")})
    if then.get("config") != now["config"] or then.get("inputs") != now["inputs"] or placement != now["placement"]:
        return "config"
    parts = [f"code {then.get('code', '?')[:8]}" if then.get("code") != now["code"] else "",
             f"dataset {then.get('dataset', '?')[:8]}" if then.get("dataset") != now["dataset"] else ""]
    return ", ".join(p for p in parts if p) or "unknown version"
