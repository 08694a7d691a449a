"""PyTorch rasterizers: the readable tile-binned reference and a dense brute-force check.

Both evaluate, for each pixel, the Gaussians in front-to-back depth order:
    alpha_i = min(0.99, opacity_i * exp(-0.5 d^T conic_i d)),  d = (u + 0.5, v + 0.5) - mean2d_i,
skipped when alpha_i < 1/255 or the pixel lies outside the Gaussian's square footprint
|d_x|, |d_y| <= radius_i (so the result does not depend on the tile size). Compositing stops before
the first Gaussian that would take the transmittance below 1e-4. Outputs: colour + T * background,
alpha = 1 - T, depth = sum of weight * z, and each Gaussian's largest weight alpha * T.
Everything is differentiable by autograd.
"""
from __future__ import annotations

import math

import torch

from recon.raster.types import ALPHA_MAX, ALPHA_MIN, T_MIN, TILE


def gaussian_alphas(px: torch.Tensor, means2d, conics, opacities, radii) -> torch.Tensor:
    """alpha [P, n] of n Gaussians at pixel centres px [P, 2] (zero where skipped)."""
    d = px[:, None, :] - means2d[None, :, :]
    dx, dy = d[..., 0], d[..., 1]
    power = -0.5 * (conics[None, :, 0] * dx * dx + conics[None, :, 2] * dy * dy) - conics[None, :, 1] * dx * dy
    alpha = torch.clamp(opacities[None, :] * torch.exp(power), max=ALPHA_MAX)
    r = radii[None, :].to(px.dtype)
    inside = (dx.abs() <= r) & (dy.abs() <= r) & (radii[None, :] > 0)
    keep = inside & (alpha >= ALPHA_MIN)
    return torch.where(keep, alpha, torch.zeros_like(alpha))


def composite(alpha: torch.Tensor, colors: torch.Tensor, depths: torch.Tensor):
    """Front-to-back compositing of alpha [P, n] (columns in depth order).

    Returns colour [P, C], depth [P], final transmittance [P], weights [P, n] (0 after the stop).
    """
    one_minus = 1.0 - alpha
    t_after = torch.cumprod(one_minus, dim=1)                      # T after each Gaussian
    t_before = torch.cat([torch.ones_like(alpha[:, :1]), t_after[:, :-1]], dim=1)
    included = t_after >= T_MIN                                    # a prefix: t_after never increases
    weights = torch.where(included, alpha * t_before, torch.zeros_like(alpha))
    ones = alpha.new_ones(alpha.shape[0])
    if alpha.shape[1] == 0:
        return alpha.new_zeros(alpha.shape[0], colors.shape[1]), alpha.new_zeros(alpha.shape[0]), ones, weights
    n_in = included.sum(dim=1)
    final_t = torch.where(n_in > 0, t_after.gather(1, (n_in - 1).clamp_min(0)[:, None])[:, 0], ones)
    return weights @ colors, weights @ depths, final_t, weights


def _pixel_centres(x0, x1, y0, y1, dtype, device):
    ys, xs = torch.meshgrid(torch.arange(y0, y1, dtype=dtype, device=device),
                            torch.arange(x0, x1, dtype=dtype, device=device), indexing="ij")
    return torch.stack([xs.reshape(-1) + 0.5, ys.reshape(-1) + 0.5], -1)


def rasterize_dense_ref(means2d, conics, depths, radii, opacities, colors, background, width, height):
    """Every Gaussian against every pixel (small scenes only): the ground truth for the others."""
    order = torch.argsort(depths, stable=True)
    px = _pixel_centres(0, width, 0, height, means2d.dtype, means2d.device)
    alpha = gaussian_alphas(px, means2d[order], conics[order], opacities[order], radii[order])
    color, depth, final_t, weights = composite(alpha, colors[order], depths[order])
    max_w = torch.zeros_like(depths)
    if weights.shape[0]:
        max_w = max_w.index_put((order,), weights.max(dim=0).values)
    image = color + final_t[:, None] * background[None, :]
    C = colors.shape[1]
    return image.reshape(height, width, C), (1 - final_t).reshape(height, width), depth.reshape(height, width), max_w


def rasterize_ref(means2d, conics, depths, radii, opacities, colors, background, width, height):
    """Tile-binned reference: per 16x16 tile, the Gaussians whose footprint overlaps it, in depth order."""
    C = colors.shape[1]
    dtype, device = means2d.dtype, means2d.device
    image = torch.zeros(height, width, C, dtype=dtype, device=device)
    alpha_img = torch.zeros(height, width, dtype=dtype, device=device)
    depth_img = torch.zeros(height, width, dtype=dtype, device=device)
    max_w = torch.zeros_like(depths)
    order = torch.argsort(depths, stable=True)
    r = radii.to(dtype)
    m = means2d.detach()
    visible = radii > 0
    for ty in range(math.ceil(height / TILE)):
        for tx in range(math.ceil(width / TILE)):
            x0, y0 = tx * TILE, ty * TILE
            x1, y1 = min(x0 + TILE, width), min(y0 + TILE, height)
            # footprint square [m - r, m + r] overlaps the tile's pixel centres [x0 + .5, x1 - .5]
            hit = visible & (m[:, 0] + r >= x0 + 0.5) & (m[:, 0] - r <= x1 - 0.5) & \
                  (m[:, 1] + r >= y0 + 0.5) & (m[:, 1] - r <= y1 - 0.5)
            idx = order[hit[order]]
            px = _pixel_centres(x0, x1, y0, y1, dtype, device)
            a = gaussian_alphas(px, means2d[idx], conics[idx], opacities[idx], radii[idx])
            color, depth, final_t, weights = composite(a, colors[idx], depths[idx])
            h, w = y1 - y0, x1 - x0
            image[y0:y1, x0:x1] = (color + final_t[:, None] * background[None, :]).reshape(h, w, C)
            alpha_img[y0:y1, x0:x1] = (1 - final_t).reshape(h, w)
            depth_img[y0:y1, x0:x1] = depth.reshape(h, w)
            if len(idx):
                max_w = max_w.index_put((idx,), torch.maximum(max_w[idx], weights.max(dim=0).values.detach()))
    return image, alpha_img, depth_img, max_w
