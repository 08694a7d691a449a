"""Image losses of the D3DGS / 3DGS recipes: L1 and D-SSIM (1 - SSIM with an 11x11 Gaussian window,
sigma 1.5, constants for data range 1, as the public 3DGS code computes it), differentiable."""
from __future__ import annotations

import torch
import torch.nn.functional as F

C1 = 0.01 ** 2
C2 = 0.03 ** 2


def _window(size: int, sigma: float, channels: int, dtype, device) -> torch.Tensor:
    x = torch.arange(size, dtype=dtype, device=device) - (size - 1) / 2
    g = torch.exp(-x * x / (2 * sigma * sigma))
    g = g / g.sum()
    return (g[:, None] @ g[None, :]).expand(channels, 1, size, size).contiguous()


def ssim(img: torch.Tensor, ref: torch.Tensor, window: int = 11, sigma: float = 1.5) -> torch.Tensor:
    """Mean SSIM of images [H, W, C] (zero-padded borders, like the 3DGS training loss)."""
    if img.shape != ref.shape:
        raise ValueError(f"ssim: shapes differ: {tuple(img.shape)} vs {tuple(ref.shape)}")
    x = img.permute(2, 0, 1)[None]
    y = ref.permute(2, 0, 1)[None]
    C = x.shape[1]
    w = _window(window, sigma, C, x.dtype, x.device)
    pad = window // 2
    mu_x = F.conv2d(x, w, padding=pad, groups=C)
    mu_y = F.conv2d(y, w, padding=pad, groups=C)
    sxx = F.conv2d(x * x, w, padding=pad, groups=C) - mu_x ** 2
    syy = F.conv2d(y * y, w, padding=pad, groups=C) - mu_y ** 2
    sxy = F.conv2d(x * y, w, padding=pad, groups=C) - mu_x * mu_y
    s = ((2 * mu_x * mu_y + C1) * (2 * sxy + C2)) / ((mu_x ** 2 + mu_y ** 2 + C1) * (sxx + syy + C2))
    return s.mean()


def l1(img: torch.Tensor, ref: torch.Tensor) -> torch.Tensor:
    return (img - ref).abs().mean()


def photometric_loss(img: torch.Tensor, ref: torch.Tensor, lambda_dssim: float = 0.2) -> torch.Tensor:
    """(1 - lambda) L1 + lambda (1 - SSIM): the D3DGS loss with lambda = 0.2."""
    return (1.0 - lambda_dssim) * l1(img, ref) + lambda_dssim * (1.0 - ssim(img, ref))
