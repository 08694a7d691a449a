"""Image metrics shared by every layer: PSNR here; SSIM and the full score set in `image`, LPIPS (offline weights) in `lpips`."""
from __future__ import annotations

import math

import numpy as np


def psnr(pred: np.ndarray, ref: np.ndarray, data_range: float = 1.0) -> float:
    """PSNR in dB of one image pair (identical images: +inf)."""
    if pred.shape != ref.shape:
        raise ValueError(f"psnr: shapes differ: {pred.shape} vs {ref.shape}")
    mse = float(np.mean((np.asarray(pred, np.float64) - np.asarray(ref, np.float64)) ** 2))
    return math.inf if mse == 0 else 10.0 * math.log10(data_range ** 2 / mse)
