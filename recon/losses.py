"""Image losses of the D3DGS / 3DGS recipes: L1 and D-SSIM (1 - SSIM with an 11x11 Gaussian window,
sigma 1.5, constants for data range 1, as the public 3DGS code computes it), differentiable."""
from __future__ import annotations

import torch
import torch.nn.functional as F

C1 = 0.01 ** 2
C2 = 0.03 ** 2


def _gaussian_1d(size: int, sigma: float, dtype, device) -> torch.Tensor:
    """The normalised 1-D Gaussian [size] whose outer product with itself is the SSIM window."""
    x = torch.arange(size, dtype=dtype, device=device) - (size - 1) / 2
    g = torch.exp(-x * x / (2 * sigma * sigma))
    return g / g.sum()


def _window(size: int, sigma: float, channels: int, dtype, device) -> torch.Tensor:
    g = _gaussian_1d(size, sigma, dtype, device)
    return (g[:, None] @ g[None, :]).expand(channels, 1, size, size).contiguous()


def _ssim_map(mu_x, mu_y, exx, eyy, exy) -> torch.Tensor:
    """Per-pixel SSIM from the windowed means of x, y, x^2, y^2 and xy."""
    sxx = exx - mu_x ** 2
    syy = eyy - mu_y ** 2
    sxy = exy - mu_x * mu_y
    return ((2 * mu_x * mu_y + C1) * (2 * sxy + C2)) / ((mu_x ** 2 + mu_y ** 2 + C1) * (sxx + syy + C2))


def _as_nchw(img: torch.Tensor, ref: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
    """Both images [H, W, C] as [1, C, H, W] views, after checking that their shapes agree."""
    if img.shape != ref.shape:
        raise ValueError(f"ssim: shapes differ: {tuple(img.shape)} vs {tuple(ref.shape)}")
    return img.permute(2, 0, 1)[None], ref.permute(2, 0, 1)[None]


def ssim_ref(img: torch.Tensor, ref: torch.Tensor, window: int = 11, sigma: float = 1.5) -> torch.Tensor:
    """Reference: mean SSIM of images [H, W, C] with the 2-D window, five depthwise convolutions
    (zero-padded borders, like the 3DGS training loss)."""
    x, y = _as_nchw(img, ref)
    C = x.shape[1]
    w = _window(window, sigma, C, x.dtype, x.device)
    pad = window // 2
    means = [F.conv2d(m, w, padding=pad, groups=C) for m in (x, y, x * x, y * y, x * y)]
    return _ssim_map(*means).mean()


def ssim(img: torch.Tensor, ref: torch.Tensor, window: int = 11, sigma: float = 1.5) -> torch.Tensor:
    """Mean SSIM of images [H, W, C]: `ssim_ref` computed fast. The window is separable, so the five
    maps go through one depthwise convolution along the rows and one along the columns (2 x 11 taps
    per pixel instead of 121; zero padding in each pass is the 2-D zero padding). On one core at
    346 x 260 forward + backward is 1.8x faster for three channels and 13x for one (torch's 2-D
    single-channel path is slow); docs/results/training_speed.md."""
    x, y = _as_nchw(img, ref)
    C = x.shape[1]
    k = 5 * C
    g = _gaussian_1d(window, sigma, x.dtype, x.device)
    pad = window // 2
    maps = torch.cat([x, y, x * x, y * y, x * y], 1)                                      # [1, 5C, H, W]
    maps = F.conv2d(maps, g.view(1, 1, 1, window).expand(k, 1, 1, window), padding=(0, pad), groups=k)
    maps = F.conv2d(maps, g.view(1, 1, window, 1).expand(k, 1, window, 1), padding=(pad, 0), groups=k)
    return _ssim_map(*maps.split(C, 1)).mean()


def l1(img: torch.Tensor, ref: torch.Tensor) -> torch.Tensor:
    return (img - ref).abs().mean()


def photometric_loss(img: torch.Tensor, ref: torch.Tensor, lambda_dssim: float = 0.2) -> torch.Tensor:
    """(1 - lambda) L1 + lambda (1 - SSIM): the D3DGS loss with lambda = 0.2."""
    return (1.0 - lambda_dssim) * l1(img, ref) + lambda_dssim * (1.0 - ssim(img, ref))
