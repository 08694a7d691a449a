"""The reconstruction API: `fit` a registered method on a generated scene, `load` a trained model.

    model = recon.fit("data/quick/lego", method="d3dgs", config="configs/recon/d3dgs_quick.yaml",
                      out_dir="runs/lego/d3dgs")
    image = model.render(camera, t)
"""
from __future__ import annotations

from pathlib import Path
from typing import Any, Callable, Mapping

import yaml

from datagen.dataset import SceneDataset
from e4dgs.config import ConfigError, from_dict, to_dict
from recon.methods import get_method
from recon.model import DynamicGaussians, load  # noqa: F401  (re-exported)
from recon.trainer import Trainer


def set_dotted(data: dict, key: str, value: Any) -> None:
    """data[a][b][c] = value for key 'a.b.c' (creating mappings on the way)."""
    parts = key.split(".")
    node = data
    for part in parts[:-1]:
        nxt = node.setdefault(part, {})
        if not isinstance(nxt, dict):
            raise ConfigError(f"{key}: {part} is not a mapping")
        node = nxt
    node[parts[-1]] = value


def parse_set(items: list[str]) -> dict[str, Any]:
    """`--set key=value` items -> {dotted key: YAML-parsed value}."""
    out = {}
    for item in items:
        if "=" not in item:
            raise ConfigError(f"--set {item!r}: expected key=value")
        key, value = item.split("=", 1)
        out[key.strip()] = yaml.safe_load(value)
    return out


def resolve_config(method: str, config: Any = None, overrides: Mapping[str, Any] | None = None):
    """A method's typed config from None (defaults), a YAML path, a mapping or an instance, with
    dotted-key overrides applied on top. Unknown keys raise ConfigError naming the key (and file)."""
    cls = get_method(method).config_cls
    source = "--set" if config is None else "<config>"
    if config is None:
        data: dict = {}
    elif isinstance(config, (str, Path)):
        source = str(config)
        try:
            data = yaml.safe_load(Path(config).read_text()) or {}
        except OSError as exc:
            raise ConfigError(f"{config}: cannot read config file ({exc.strerror})") from None
        if not isinstance(data, dict):
            raise ConfigError(f"{config}: expected a mapping at the top level")
    elif isinstance(config, Mapping):
        data = dict(config)
    elif isinstance(config, cls):
        data = to_dict(config)
    else:
        raise TypeError(f"config must be None, a YAML path, a mapping or a {cls.__name__}, got {type(config).__name__}")
    for key, value in (overrides or {}).items():
        set_dotted(data, key, value)
    try:
        return from_dict(cls, data)
    except ConfigError as exc:
        raise ConfigError(f"{source}: {exc}") from None


def fit(scene_dir: str | Path, method: str = "d3dgs", config: Any = None, out_dir: str | Path | None = None,
        overrides: Mapping[str, Any] | None = None, progress: bool = True,
        on_iteration: Callable | None = None) -> DynamicGaussians:
    """Train `method` on the scene at `scene_dir`; resumes a killed run in `out_dir`, and returns the
    finished model directly if `out_dir` already holds it. out_dir defaults to runs/<scene>/<method>."""
    dataset = SceneDataset(scene_dir)
    cfg = resolve_config(method, config, overrides)
    out = Path(out_dir) if out_dir is not None else Path("runs") / dataset.dir.name / method
    return Trainer(get_method(method)(dataset, cfg), out, progress, on_iteration).run()
