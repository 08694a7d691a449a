"""Event supervision of E-4DGS as pure functions (paper, sections 3.2 and 3.4).

Ground truth of a window (t_start, t_end]:
    dE_gt(u)  = sum over its events at u of p * C^p      (log units; C^p the simulator's thresholds)
    N_gt(u)   = dE_gt(u) / C_ref                        (C_ref = (C+ + C-) / 2; = the signed count when
                                                         C+ = C-), and on pixels without events
                                                         dE_gt gets Gaussian noise of std sigma (ESS jitter)
Prediction from two renders of the model at the window's end points:
    N_pred(u) = (L_hat(u, t_end) - L_hat(u, t_start)) / C_hat,   L_hat = response(linear(render))
Loss: L_recon = mean_u sqrt((N_gt - N_pred)^2 + eps^2), eps = 1e-3; L_TV = mean |grad| of the
rendered image (anisotropic total variation).
"""
from __future__ import annotations

import math

import numpy as np
import torch

from common.color import REC709_LUMA
from eventio.representations.count_image import count_image


def event_maps(x, y, p, width: int, height: int, c_pos: float, c_neg: float) -> tuple[np.ndarray, np.ndarray]:
    """(dE_gt [H, W] = sum p C^p in log units, triggered [H, W] bool: pixel has at least one event),
    from the window's ON and OFF count images."""
    on, off = count_image(x, y, p, width, height, split=True)
    return c_pos * on - c_neg * off, (on + off) > 0


def gt_counts(de_gt: np.ndarray, triggered: np.ndarray, c_ref: float, noise_sigma: float,
              rng: np.random.Generator | None) -> np.ndarray:
    """N_gt [H, W] float32: dE_gt / C_ref, with N(0, noise_sigma^2) (log units) on event-free pixels."""
    de = np.array(de_gt, np.float64)
    if noise_sigma > 0 and rng is not None:
        quiet = ~triggered
        de[quiet] = rng.normal(0.0, noise_sigma, int(quiet.sum()))
    return (de / c_ref).astype(np.float32)


def srgb_to_linear_t(v: torch.Tensor) -> torch.Tensor:
    """Differentiable sRGB decoding (values above 1 follow the power branch)."""
    v = v.clamp_min(0.0)
    return torch.where(v <= 0.04045, v / 12.92, ((v + 0.055) / 1.055) ** 2.4)


def linear_to_srgb_t(v: torch.Tensor) -> torch.Tensor:
    """Differentiable sRGB encoding of linear light (not clipped above 1)."""
    v = v.clamp_min(0.0)
    return torch.where(v <= 0.0031308, 12.92 * v, 1.055 * v.clamp_min(0.0031308) ** (1 / 2.4) - 0.055)


def exposure_mean(images: list[torch.Tensor]) -> torch.Tensor:
    """A blurred frame from renders [H, W, C] (sRGB-encoded) spread over its exposure: the mean in linear
    light, re-encoded (how the dataset made its blurred frames). One render is returned as is."""
    if len(images) == 1:
        return images[0]
    return linear_to_srgb_t(torch.stack([srgb_to_linear_t(im) for im in images]).mean(0))


def luminance_t(linear: torch.Tensor) -> torch.Tensor:
    """[H, W, C] linear -> [H, W] (C = 1: itself; C = 3: Rec.709 luma)."""
    if linear.shape[-1] == 1:
        return linear[..., 0]
    w = torch.tensor(REC709_LUMA, dtype=linear.dtype, device=linear.device)
    return linear @ w


def log_response_t(linear: torch.Tensor, mode: str = "log", eps: float = 1e-3, linlog_threshold_dn: float = 20.0,
                   dn_per_unit: float = 255.0) -> torch.Tensor:
    """The simulator's response in torch: log(I + eps), or v2e's lin-log on DN = dn_per_unit * I."""
    if mode == "log":
        return torch.log(linear.clamp_min(0.0) + eps)
    if mode == "linlog":
        dn = linear.clamp_min(0.0) * dn_per_unit
        slope = math.log(linlog_threshold_dn) / linlog_threshold_dn
        return torch.where(dn <= linlog_threshold_dn, dn * slope, torch.log(dn.clamp_min(linlog_threshold_dn)))
    raise ValueError(f"unknown response mode {mode!r} (expected 'log' or 'linlog')")


def predicted_counts(l_start: torch.Tensor, l_end: torch.Tensor, c_hat: torch.Tensor) -> torch.Tensor:
    """N_pred = (L_hat(t_end) - L_hat(t_start)) / C_hat, [H, W]."""
    return (l_end - l_start) / c_hat


def recon_loss(n_gt: torch.Tensor, n_pred: torch.Tensor, eps: float = 1e-3) -> torch.Tensor:
    """mean sqrt((N_gt - N_pred)^2 + eps^2): a smooth L1 that stays differentiable at 0."""
    return torch.sqrt((n_gt - n_pred) ** 2 + eps * eps).mean()


def tv_loss(img: torch.Tensor) -> torch.Tensor:
    """Anisotropic total variation of an image [H, W] or [H, W, C]: mean absolute neighbour difference."""
    dy = (img[1:] - img[:-1]).abs().mean() if img.shape[0] > 1 else img.new_zeros(())
    dx = (img[:, 1:] - img[:, :-1]).abs().mean() if img.shape[1] > 1 else img.new_zeros(())
    return dx + dy


def activity_mask(counts: np.ndarray, min_events: int, dilate_px: int) -> np.ndarray:
    """Pixels where the scene changed: [H, W] bool from event counts per pixel [H, W] (any sign).

    A pixel is active when its 3x3 neighbourhood holds at least `min_events` events (isolated noise
    events do not count), and the active set is then grown by `dilate_px` pixels (a square), so a
    carving that requires every view to agree errs on the side of keeping.
    """
    c = np.abs(np.asarray(counts, np.float64))
    pad = np.pad(c, 1)
    box = sum(pad[1 + dy:1 + dy + c.shape[0], 1 + dx:1 + dx + c.shape[1]]
              for dy in (-1, 0, 1) for dx in (-1, 0, 1))
    active = box >= min_events
    if dilate_px > 0:
        r = dilate_px
        pad = np.pad(active, r)
        grown = np.zeros_like(active)
        for dy in range(-r, r + 1):
            for dx in range(-r, r + 1):
                grown |= pad[r + dy:r + dy + c.shape[0], r + dx:r + dx + c.shape[1]]
        active = grown
    return active


def multiscale_recon_loss(n_gt: torch.Tensor, n_pred: torch.Tensor, scales: tuple[int, ...],
                          eps: float = 1e-3) -> torch.Tensor:
    """Mean over `scales` of recon_loss between the count maps [H, W] averaged over s x s pixel blocks.

    Counts are linear in log intensity, so the block mean of N is the change of the block-mean log
    intensity: at a coarse scale the loss compares the low-frequency layout of L(t_end) - L(t_start),
    where a fine texture the model cannot resolve yet averages out instead of giving every Gaussian's
    colour a gradient of random sign. Scale 1 is the paper's per-pixel loss.
    """
    total = n_gt.new_zeros(())
    for s in scales:
        if s == 1:
            total = total + recon_loss(n_gt, n_pred, eps)
        else:
            pool = lambda m: torch.nn.functional.avg_pool2d(m[None, None], s, ceil_mode=True)[0, 0]  # noqa: E731
            total = total + recon_loss(pool(n_gt), pool(n_pred), eps)
    return total / len(scales)
