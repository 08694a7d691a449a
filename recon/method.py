"""The hooks a reconstruction method implements for the shared trainer and the class-level half that
scoring needs (recon.scoring.Scorer): subclass `Method` and `@register` it. Training hooks receive a
`StepContext` (what they may use of the trainer), so this file does not import the trainer."""
from __future__ import annotations

import hashlib
from pathlib import Path

from typing import Any, Callable, Protocol

import numpy as np
import torch

from scene_format.reader import SceneDataset
from recon.model import DynamicGaussians
from recon.scoring import Scorer

class StepContext(Protocol):
    """What a method's training hooks may use of the trainer that calls them (recon.trainer.Trainer is
    one): the model being trained, the raster backend, the training's random generator, the next
    view index of a shuffled epoch, the training config, and this iteration's coarse-to-fine factor
    (render through recon.coarse.coarse_camera and reduce the targets with recon.coarse; 1: full size)."""
    model: DynamicGaussians
    backend: str
    rng: np.random.Generator
    tcfg: Any
    render_factor: int

    def next_index(self, n: int) -> int: ...


class Method:
    """Hooks a method implements (subclass it and `@register` it)."""
    name = ""
    config_cls: type = object
    blur_level_field: str | None = None   # the config field that picks the RGB blur level it trains on (None: none)
    # what it sees: ("rgb",), ("events",) or ("events", "rgb"). Scoring follows it: a method that
    # sees no RGB has no absolute intensity and is scored after its `correction`; the tables read it
    inputs: tuple[str, ...] = ()

    def __init__(self, dataset: SceneDataset, cfg: Any):
        self.dataset, self.cfg = dataset, cfg

    # -- scoring (class level: needs the config, not the training data) ---------------------------
    @classmethod
    def channels_of(cls, cfg: Any) -> int:
        """Channels the method's model predicts under `cfg`."""
        raise NotImplementedError

    @classmethod
    def correction(cls, cfg: Any) -> Callable[[np.ndarray, np.ndarray], np.ndarray] | None:
        """What is applied to a prediction before it is scored (None: nothing; E-4DGS: colour correction)."""
        return None

    @classmethod
    def input_files(cls, cfg: Any) -> dict[str, Path]:
        """Files outside the config and the scene that the trained model depends on (E2VID + D3DGS: the
        network's weights); their contents are part of a benchmark run's identity (`input_digests`)."""
        return {}

    @classmethod
    def input_digests(cls, cfg: Any) -> dict[str, str]:
        """{"<name>_sha256": hex digest} of each of `input_files`."""
        return {f"{name}_sha256": hashlib.sha256(Path(path).read_bytes()).hexdigest()
                for name, path in sorted(cls.input_files(cfg).items())}

    @classmethod
    def scorer(cls, dataset: SceneDataset, cfg: Any) -> Scorer:
        """The method's evaluation on `dataset`, without loading or reconstructing training data."""
        return Scorer(dataset, cls.channels_of(cfg), cls.correction(cfg))

    def channels(self) -> int:
        return type(self).channels_of(self.cfg)

    def setup_model(self, model: DynamicGaussians) -> None:
        """Adjust a freshly initialised model (e.g. give it deformation anchors)."""

    def to_device(self, device: torch.device) -> None:
        """Move the method's training data (targets, cameras) and parameters to the run's device
        (called once, before the optimizer is built)."""

    def extra_parameters(self) -> list[dict]:
        """Additional Adam groups (dicts with params, lr, name)."""
        return []

    def step(self, trainer: StepContext, iteration: int):
        """Loss of one iteration -> (loss tensor, [(RenderOutput, Camera)] whose means2d kept their grad)."""
        raise NotImplementedError

    def prune_mask(self, trainer: StepContext, iteration: int) -> torch.Tensor | None:
        """Gaussians to prune at this iteration (bool [N]) or None (called every iteration, after backward)."""
        return None

    def eval_pairs(self, model: DynamicGaussians, records, backend: str = "auto") -> list[tuple[np.ndarray, np.ndarray]]:
        """(prediction, ground truth) pairs of held-out records (see recon.scoring.Scorer)."""
        return type(self).scorer(self.dataset, self.cfg).eval_pairs(model, records, backend)

    def state_dict(self) -> dict:
        return {}

    def load_state_dict(self, state: dict) -> None:
        pass
