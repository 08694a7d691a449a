"""Per-image PSNR / SSIM / LPIPS, then means over images (never one PSNR of a whole batch).

SSIM is scikit-image's `structural_similarity` with the settings of Wang et al. (and of the
D3DGS / E-4DGS evaluation scripts): Gaussian window sigma 1.5, population covariance, data range 1,
averaged over channels for colour images.
"""
from __future__ import annotations

import math
from typing import Iterable

import numpy as np
from skimage.metrics import structural_similarity

from common.color import srgb_luma
from common.metrics import psnr


def ssim(pred: np.ndarray, ref: np.ndarray) -> float:
    """SSIM of one image pair [H, W] or [H, W, C] in [0, 1]."""
    if pred.shape != ref.shape:
        raise ValueError(f"ssim: shapes differ: {pred.shape} vs {ref.shape}")
    p = np.asarray(pred, np.float64)
    r = np.asarray(ref, np.float64)
    if p.ndim == 3 and p.shape[-1] == 1:
        p, r = p[..., 0], r[..., 0]
    return float(structural_similarity(p, r, data_range=1.0, gaussian_weights=True, sigma=1.5,
                                       use_sample_covariance=False,
                                       channel_axis=-1 if p.ndim == 3 else None))


def luma(image: np.ndarray) -> np.ndarray:
    """[H, W, 3] sRGB-encoded -> [H, W, 1] sRGB-encoded Rec.709 luma of its linear light (how the
    dataset's gray/ frames are made); a single-channel image [H, W(, 1)] is returned as it is."""
    if image.ndim == 3 and image.shape[-1] == 3:
        return srgb_luma(image)[..., None]
    return image


def score_pairs(pairs: Iterable[tuple[np.ndarray, np.ndarray]], lpips_net: str | None = "vgg") -> dict[str, float]:
    """Mean PSNR / SSIM (/ LPIPS) over (prediction, ground truth) pairs; inf PSNRs are capped at 100 dB.
    `psnr_luma` is the PSNR of both images' luma: the target events-only methods are scored on, so
    colour and grayscale methods can be compared on the same quantity (equal to `psnr` for gray)."""
    pairs = list(pairs)
    if not pairs:
        raise ValueError("score_pairs: no image pairs")
    out = {"psnr": float(np.mean([min(psnr(p, r), 100.0) for p, r in pairs])),
           "psnr_luma": float(np.mean([min(psnr(luma(p), luma(r)), 100.0) for p, r in pairs])),
           "ssim": float(np.mean([ssim(p, r) for p, r in pairs])),
           "n_images": len(pairs)}
    if lpips_net:
        from common.metrics.lpips import lpips_distance
        out["lpips"] = float(np.mean([lpips_distance(p, r, lpips_net) for p, r in pairs]))
    assert all(math.isfinite(v) for v in out.values())
    return out
