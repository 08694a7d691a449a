"""Held-out evaluation used during training (the benchmark's full metrics live in common/metrics)."""
from __future__ import annotations

from typing import Iterable

import numpy as np

from common.metrics import psnr


def evaluate_psnr(pairs: Iterable[tuple[np.ndarray, np.ndarray]]) -> float:
    """Mean over images of the per-image PSNR (never one PSNR of the whole batch)."""
    values = [psnr(p, r) for p, r in pairs]
    if not values:
        raise ValueError("evaluate_psnr: no image pairs")
    return float(np.mean(values))
