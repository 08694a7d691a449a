"""What evaluating a method needs, apart from training it: held-out views rendered from a model,
their ground truth in the method's channels, and the method's correction before scoring.

    scorer = recon.get_method("e4dgs").scorer(dataset, cfg)   # no training data loaded
    pairs = scorer.eval_pairs(model, dataset.frames("test"))  # [(prediction, ground truth)] in [0, 1]
"""
from __future__ import annotations

from typing import Callable

import numpy as np

from common.metrics import psnr
from scene_format.reader import SceneDataset
from recon.model import DynamicGaussians
from recon.dataset_views import load_frame, record_camera


def checked_pairs(method_cls: type, pairs, records, what: str) -> list:
    """The (prediction, ground truth) pairs of `records` as a list, or ValueError naming the method's
    class when they are not one same-shaped pair per record (a plug-in that renders no views)."""
    pairs = list(pairs)
    who = f"method {getattr(method_cls, 'name', '?')!r} ({method_cls.__module__}.{method_cls.__qualname__})"
    if len(pairs) != len(records):
        raise ValueError(f"{who}: its scorer gave {len(pairs)} (prediction, ground truth) pairs for {len(records)} {what}")
    for rec, (pred, gt) in zip(records, pairs):
        if np.shape(pred) != np.shape(gt):
            raise ValueError(f"{who}: its render of view {rec.stem} is {np.shape(pred)}, the view is {np.shape(gt)}")
    return pairs


class Scorer:
    def __init__(self, dataset: SceneDataset, channels: int,
                 correct: Callable[[np.ndarray, np.ndarray], np.ndarray] | None = None):
        self.dataset = dataset
        self.n_channels = channels
        self._correct = correct

    def channels(self) -> int:
        return self.n_channels

    def correct(self, pred: np.ndarray, gt: np.ndarray) -> np.ndarray:
        """What is applied to a prediction before it is scored (identity unless the method has one)."""
        return pred if self._correct is None else self._correct(pred, gt)

    def eval_pairs(self, model: DynamicGaussians, records, backend: str = "auto") -> list[tuple[np.ndarray, np.ndarray]]:
        """(prediction, ground truth) images [H, W, C] in [0, 1] on the CPU for held-out records,
        rendered on the model's device with `backend`."""
        pairs = []
        for rec in records:
            gt = load_frame(self.dataset, rec, self.n_channels)
            pred = model.render_numpy(record_camera(self.dataset, rec), rec.time, backend)
            pairs.append((self.correct(pred, gt), gt))
        return pairs


def evaluate_psnr(pairs) -> float:
    """Mean over images of the per-image PSNR of (prediction, ground truth) pairs (never one PSNR of
    the whole batch): the trainer's progress figure (the benchmark's full metrics: common.metrics)."""
    values = [psnr(p, r) for p, r in pairs]
    if not values:
        raise ValueError("evaluate_psnr: no image pairs")
    return float(np.mean(values))
