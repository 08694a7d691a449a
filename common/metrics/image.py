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

SSIM_PAD = 5        # (window 11 - 1) / 2: the border skimage leaves out of the mean for sigma 1.5


def ssim(pred: np.ndarray, ref: np.ndarray) -> float:
    """SSIM of one image pair [H, W] or [H, W, C] in [0, 1]."""
    return ssim_with_region(pred, ref)[0]


def ssim_with_region(pred: np.ndarray, ref: np.ndarray, mask: np.ndarray | None = None) -> tuple[float, float | None]:
    """(SSIM of the pair, mean of its SSIM map over `mask` [H, W] bool, or None). Like the whole-image
    value, the region's mean leaves out the filter radius (5 px) along the border; a mask of ones
    gives the whole-image SSIM."""
    if pred.shape != ref.shape:
        raise ValueError(f"ssim: shapes differ: {pred.shape} vs {ref.shape}")
    p = np.asarray(pred, np.float64)
    r = np.asarray(ref, np.float64)
    if p.ndim == 3 and p.shape[-1] == 1:
        p, r = p[..., 0], r[..., 0]
    whole, smap = structural_similarity(p, r, data_range=1.0, gaussian_weights=True, sigma=1.5,
                                        use_sample_covariance=False, channel_axis=-1 if p.ndim == 3 else None,
                                        full=True)
    if mask is None:
        return float(whole), None
    inner = np.zeros(mask.shape, bool)
    inner[SSIM_PAD:-SSIM_PAD, SSIM_PAD:-SSIM_PAD] = mask[SSIM_PAD:-SSIM_PAD, SSIM_PAD:-SSIM_PAD]
    if not inner.any():
        return float(whole), None
    return float(whole), float(smap[inner].mean())


def psnr_region(pred: np.ndarray, ref: np.ndarray, mask: np.ndarray) -> float:
    """PSNR over the pixels of `mask` [H, W] bool (every channel), capped at 100 dB."""
    d = (np.asarray(pred, np.float64) - np.asarray(ref, np.float64))[mask]
    mse = float(np.mean(d * d))
    return min(100.0, 10.0 * np.log10(1.0 / mse)) if mse > 0 else 100.0


def luma(image: np.ndarray) -> np.ndarray:
    """[H, W, 3] sRGB-encoded -> [H, W, 1] sRGB-encoded Rec.709 luma of its linear light (how the
    dataset's gray/ frames are made); a single-channel image [H, W(, 1)] is returned as it is."""
    if image.ndim == 3 and image.shape[-1] == 3:
        return srgb_luma(image)[..., None]
    return image


def view_scores(pairs: Iterable[tuple[np.ndarray, np.ndarray]], lpips_net: str | None = "vgg",
                masks: list[np.ndarray | None] | None = None) -> list[dict[str, float]]:
    """Per (prediction, ground truth) pair: psnr (capped at 100 dB), psnr_luma, ssim (/ lpips), and
    where its mask (a dynamic-region mask [H, W] bool, or None) has pixels, the same over them
    (psnr_dyn, psnr_luma_dyn, ssim_dyn unless the mask lies within the SSIM border, lpips_dyn) and
    dyn_fraction (the masked share of its pixels; 0 without mask)."""
    pairs = list(pairs)
    if not pairs:
        raise ValueError("score_pairs: no image pairs")
    masks = list(masks) if masks is not None else [None] * len(pairs)
    if len(masks) != len(pairs):
        raise ValueError(f"score_pairs: {len(masks)} masks for {len(pairs)} pairs")
    out = []
    for (p, r), m in zip(pairs, masks):
        m = m if m is not None and m.any() else None
        whole, region = ssim_with_region(p, r, m)
        v = {"psnr": min(psnr(p, r), 100.0), "psnr_luma": min(psnr(luma(p), luma(r)), 100.0), "ssim": whole,
             "dyn_fraction": float(m.mean()) if m is not None else 0.0}
        if m is not None:
            v.update(psnr_dyn=psnr_region(p, r, m), psnr_luma_dyn=psnr_region(luma(p), luma(r), m))
            if region is not None:
                v["ssim_dyn"] = region
        if lpips_net:
            from common.metrics.lpips import lpips_with_region
            v["lpips"], region_lpips = lpips_with_region(p, r, lpips_net, m)
            if m is not None and region_lpips is not None:
                v["lpips_dyn"] = region_lpips
        out.append({k: float(x) for k, x in v.items()})
    return out


def mean_scores(views: list[dict[str, float]]) -> dict[str, float]:
    """The scores of a set of views from their view_scores: means over every view (psnr, psnr_luma,
    ssim, lpips, n_images) and, where some views have a dynamic region, means over those
    (psnr_dyn, psnr_luma_dyn, ssim_dyn, lpips_dyn, n_dyn_images) and dyn_fraction over every view."""
    out = {k: float(np.mean([v[k] for v in views])) for k in ("psnr", "psnr_luma", "ssim", "lpips") if k in views[0]}
    out["n_images"] = len(views)
    dyn = [v for v in views if "psnr_dyn" in v]
    if dyn:
        out.update(psnr_dyn=float(np.mean([v["psnr_dyn"] for v in dyn])),
                   psnr_luma_dyn=float(np.mean([v["psnr_luma_dyn"] for v in dyn])),
                   n_dyn_images=len(dyn), dyn_fraction=float(np.mean([v["dyn_fraction"] for v in views])))
        for k in ("ssim_dyn", "lpips_dyn"):               # masks within the border have no region SSIM
            vals = [v[k] for v in dyn if k in v]
            if vals:
                out[k] = float(np.mean(vals))
    assert all(math.isfinite(v) for v in out.values())
    return out


def score_pairs(pairs: Iterable[tuple[np.ndarray, np.ndarray]], lpips_net: str | None = "vgg",
                masks: list[np.ndarray | None] | None = None) -> dict[str, float]:
    """Mean PSNR / SSIM (/ LPIPS) over (prediction, ground truth) pairs; inf PSNRs are capped at 100 dB.
    `psnr_luma` is the PSNR of both images' luma: the target events-only methods are scored on, so
    colour and grayscale methods can be compared on the same quantity (equal to `psnr` for gray).

    With `masks` (a dynamic-region mask [H, W] bool, or None, per pair) the same scores over the masked
    pixels are added as psnr_dyn / psnr_luma_dyn / ssim_dyn (/ lpips_dyn): means over the views whose
    mask has pixels (`n_dyn_images`), and `dyn_fraction`, the masked share of all pixels."""
    return mean_scores(view_scores(pairs, lpips_net, masks))
