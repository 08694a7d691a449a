"""The reconstruction API: `fit` a registered method on a generated scene, `load` a trained model.

    model = recon.fit("data/quick/lego", method="d3dgs", config="configs/recon/d3dgs_quick.yaml",
                      out_dir="runs/lego/d3dgs")
    image = model.render(camera, t)
    scores = recon.evaluate(model, "data/quick/lego")     # {psnr, ssim[, lpips], n_images} on the test views
"""
from __future__ import annotations

from pathlib import Path
from typing import Any, Callable, Mapping

from scene_format.reader import SceneDataset
from common.config import build_config, parse_set, set_dotted  # noqa: F401  (parse_set, set_dotted re-exported)
from recon.methods import get_method
from recon.model import DynamicGaussians, load  # noqa: F401  (re-exported)
from recon.trainer import Trainer


def resolve_config(method: str, config: Any = None, overrides: Mapping[str, Any] | None = None,
                   overrides_source: str = "--set"):
    """A method's typed config from None (defaults), a YAML path, a mapping or an instance, with
    dotted-key overrides applied on top. Unknown keys raise ConfigError naming the key and its source
    (the file, or `overrides_source` for an override)."""
    return build_config(get_method(method).config_cls, config, overrides, overrides_source)


def fit(scene_dir: str | Path, method: str = "d3dgs", config: Any = None, out_dir: str | Path | None = None,
        overrides: Mapping[str, Any] | None = None, progress: bool = True,
        on_iteration: Callable | None = None) -> DynamicGaussians:
    """Train `method` on the scene at `scene_dir`; resumes a killed run in `out_dir`, and returns the
    finished model directly if `out_dir` already holds it. out_dir defaults to runs/<scene>/<method>."""
    dataset = SceneDataset(scene_dir)
    cfg = resolve_config(method, config, overrides)
    out = Path(out_dir) if out_dir is not None else Path("runs") / dataset.dir.name / method
    if out_dir is None and (out / "model.pt").exists():
        print(f"fit: {out} holds a finished {method} model of this scene: it is returned as it is "
              "(give out_dir for a new run)")
    return Trainer(get_method(method)(dataset, cfg), out, progress, on_iteration).run()


def evaluate(model: DynamicGaussians, scene_dir: str | Path, split: str = "test", lpips_net: str | None = None,
             backend: str = "auto") -> dict:
    """Scores of a trained model on a scene's held-out views, the way the benchmark scores them: the
    model's own method and config (stored in it) pick the channels and the correction (E-4DGS's
    log-intensity gain / offset), then mean per-image PSNR / SSIM (/ LPIPS with lpips_net)."""
    from common.metrics.image import score_pairs

    dataset = SceneDataset(scene_dir)
    method = get_method(model.meta.method)
    cfg = resolve_config(model.meta.method, model.meta.config or None)
    pairs = method.scorer(dataset, cfg).eval_pairs(model, dataset.frames(split), backend)
    return score_pairs(pairs, lpips_net=lpips_net)
