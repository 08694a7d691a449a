"""The reconstruction API: `fit` a registered method on a generated scene, `load` a trained model.

    result = recon.fit("data/quick/lego", method="d3dgs", config="quick",
                       out_dir="runs/lego/d3dgs")       # a TrainResult: .model, .run_dir, .log, .train_s, ...
    image = result.model.render(camera, t)
    scores = recon.evaluate(result.model, "data/quick/lego")   # {psnr, ssim[, lpips], n_images} on the test views
"""
from __future__ import annotations

import json
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Callable, Mapping

from scene_format.reader import SceneDataset
from common.config import ConfigError, build_config, parse_set, set_dotted  # noqa: F401  (parse_set, set_dotted re-exported)
from common.fileio import output_inside_input
from recon.methods import get_method
from recon.scoring import checked_pairs
from recon.model import DynamicGaussians, load  # noqa: F401  (re-exported)
from recon.trainer import Trainer


def config_path(config: str | Path, method: str | None = None) -> Path:
    """A training recipe's file: the path as given when it exists; else, from any working folder, the
    same relative path in the toolkit's checkout, or a shipped recipe's name: `quick` for `method`
    (configs/recipes/<method>/quick.yaml), `e4dgs/quick`, `d3dgs/mlp` (common.config_files; names
    from before 0.2 resolve with a deprecation line). ConfigError naming the path and the shipped
    names otherwise."""
    from common.config_files import find, shipped_names

    found = find("recipes", config, method)
    if found is None:
        raise ConfigError(f"{config}: cannot read config file (no such file, nor a shipped recipe of that name; "
                          f"shipped: {', '.join(shipped_names('recipes'))})")
    return found


def resolve_config(method: str, config: Any = None, overrides: Mapping[str, Any] | None = None,
                   overrides_source: str = "--set"):
    """A method's typed config from None (defaults), a YAML path, a mapping or an instance, with
    dotted-key overrides applied on top. Unknown keys raise ConfigError naming the key and its source
    (the file, or `overrides_source` for an override). A path is found as `config_path` says."""
    if isinstance(config, (str, Path)):
        config = config_path(config, method)
    return build_config(get_method(method).config_cls, config, overrides, overrides_source)


@dataclass(frozen=True)
class TrainResult:
    """What `fit` returns: the trained model and where, how and how long it was trained."""
    model: DynamicGaussians
    run_dir: Path                 # the training folder (run.json, log.jsonl, snapshots/, model.pt)
    fingerprint: str              # the run's identity: method, resolved config, its inputs, the scene's manifest
    log: tuple[dict, ...]         # the rows of log.jsonl, oldest first
    device: str                   # where it trained ("cpu", "cuda:0")
    backend: str                  # the rasterizer it trained with (cpu, torch, gsplat)
    train_s: float                # training wall-clock seconds, summed over resumes, evaluation excluded
    elapsed_s: float              # this call's seconds (set-up, resume or reuse of a finished run included)
    initial: DynamicGaussians | None = field(default=None, repr=False)   # the untrained model, when asked for

    @property
    def method(self) -> str:
        return self.model.meta.method

    @property
    def iterations(self) -> int:
        return self.model.meta.iteration

    @property
    def last_test_psnr(self) -> tuple[float, str] | None:
        """(test PSNR in dB, what it compares: rgb, or gray after the gain/offset fit) of the last
        evaluation in the log; None when the log has none."""
        evals = [r for r in self.log if "test_psnr" in r]
        return (evals[-1]["test_psnr"], evals[-1].get("test_psnr_on", "rgb")) if evals else None


def construct_method(method: str, dataset: SceneDataset, cfg):
    """The method's object for a scene; a plug-in whose constructor fails is named (TrainingError)."""
    from recon.trainer import BUNDLED_PACKAGES, TrainingError

    cls = get_method(method)
    try:
        return cls(dataset, cfg)
    except (TrainingError, KeyboardInterrupt):
        raise
    except Exception as exc:
        if cls.__module__.split(".")[0] in BUNDLED_PACKAGES:
            raise
        raise TrainingError(f"method {method!r} (plug-in class {cls.__module__}.{cls.__qualname__}): its constructor "
                            f"raised {type(exc).__name__}: {exc}") from exc


def fit(scene_dir: str | Path | SceneDataset, method: str = "d3dgs", config: Any = None, out_dir: str | Path | None = None,
        overrides: Mapping[str, Any] | None = None, progress: bool = True,
        on_iteration: Callable | None = None, keep_initial: bool = False) -> TrainResult:
    """Train `method` on the scene at `scene_dir` (a folder, or one already opened); resumes a killed
    run in `out_dir`, and returns the finished run as it is if `out_dir` already holds it. out_dir
    defaults to runs/<scene>/<method>. `config` is None (defaults), a YAML path, a mapping or the
    method's typed config (used as it is when no overrides come with it). `keep_initial` also returns
    the untrained model the run starts from (the benchmark's floor)."""
    t0 = time.time()
    dataset = scene_dir if isinstance(scene_dir, SceneDataset) else SceneDataset(scene_dir)
    typed = isinstance(config, get_method(method).config_cls) and not overrides
    cfg = config if typed else resolve_config(method, config, overrides)
    out = Path(out_dir) if out_dir is not None else Path("runs") / dataset.dir.name / method
    inside = output_inside_input(out, {"the scene folder": dataset.dir})
    if inside:
        raise ValueError(f"out_dir: {inside}")
    from common.machine import available_memory_bytes
    from recon.memory import check_fits

    if hasattr(cfg, "train"):
        check_fits(cfg.train, dataset.scene.kind, available_memory_bytes())
    if out_dir is None and (out / "model.pt").exists():
        print(f"fit: {out} holds a finished {method} model of this scene: it is returned as it is "
              "(give out_dir for a new run)")
    trainer = Trainer(construct_method(method, dataset, cfg), out, progress, on_iteration)
    initial = trainer.initial_model() if keep_initial else None
    model = trainer.run()
    # the trainer's own log (kept across resumes); a finished run returned as it is has only its file
    log = tuple(trainer.log) if trainer.log else tuple(json.loads(line) for line in (out / "log.jsonl").read_text().splitlines())
    return TrainResult(model=model, run_dir=out, fingerprint=trainer.fingerprint, log=log,
                       device=str(trainer.device), backend=trainer.backend,
                       train_s=float(log[-1]["wall_s"]) if log else 0.0, elapsed_s=time.time() - t0, initial=initial)


def evaluate(model: DynamicGaussians, scene_dir: str | Path | SceneDataset, split: str = "test",
             lpips_net: str | None = None, backend: str = "auto", device: str | None = None, dynamic: bool = True,
             config: Any = None, views_out: str | Path | None = None, views_meta: dict | None = None) -> dict:
    """Scores of a trained model on a scene's held-out views, the way the benchmark scores them: the
    model's own method and config (stored in it) pick the channels and the correction (E-4DGS's
    log-intensity gain / offset), then mean per-image PSNR / SSIM (/ LPIPS with lpips_net); where the
    scene has dynamic-region masks (and `dynamic`), the same over the moving pixels (`*_dyn`).
    `scene_dir` is a scene folder or one already opened. Rendered on `device` (default: where the model
    is) with `backend`. `config`: the model's method config already resolved (default: resolved from
    the model's own). With `views_out`, the predictions are scored as 16-bit images and kept there with
    every view's scores (recon.view_record: views.json, with `views_meta`: what the caller says the
    views belong to, e.g. the benchmark's run folder and identity), and the result adds
    `views_sha256`, the digest of views.json."""
    from common.metrics.image import mean_scores, score_pairs, view_scores

    dataset = scene_dir if isinstance(scene_dir, SceneDataset) else SceneDataset(scene_dir)
    if model.meta.scene and model.meta.scene != dataset.scene.name:
        raise ValueError(f"{dataset.dir}: the model was trained on scene {model.meta.scene!r}, these are the views of "
                         f"{dataset.scene.name!r}; its scores would compare two different scenes")
    method = get_method(model.meta.method)
    cfg = config if config is not None else resolve_config(model.meta.method, model.meta.config or None)
    records = dataset.frames(split)
    masks = [dataset.dynamic_mask(r) for r in records] if dynamic else []
    if device is not None:
        model = model.to(device)
    pairs = checked_pairs(method, method.scorer(dataset, cfg).eval_pairs(model, records, backend), records,
                          f"the {split} views of {dataset.dir}")
    masks = masks if any(m is not None for m in masks) else None
    if views_out is None:
        return score_pairs(pairs, lpips_net=lpips_net, masks=masks)
    from recon.view_record import quantized, write_views

    preds = [quantized(p) for p, _ in pairs]
    views = view_scores([(p, gt) for p, (_, gt) in zip(preds, pairs)], lpips_net, masks)
    means = mean_scores(views)
    digest = write_views(Path(views_out), [r.stem for r in records], preds, views, means,
                         {"scene": dataset.scene.name, "split": split, "lpips_net": lpips_net,
                          "method": model.meta.method, "iteration": model.meta.iteration, **(views_meta or {})})
    return {**means, "views_sha256": digest}
