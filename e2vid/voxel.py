"""E2VID's input: a window's voxel grid (eventio.representations.voxel_grid: B temporal bins with
bilinear weights in time) and E2VID's normalisation: the nonzero cells are shifted and scaled to mean 0
and standard deviation 1; zero cells stay 0.
"""
from __future__ import annotations

import torch

from eventio.representations.voxel_grid import voxel_grid, voxel_grid_events, voxel_grid_ref  # noqa: F401 (e2vid's input)


def normalize_voxel(grid: torch.Tensor) -> torch.Tensor:
    """E2VID's normalisation of one grid [B, H, W] (or a batch [N, B, H, W], each grid on its own):
    nonzero cells -> mean 0, std 1; zero cells stay 0; an empty grid (or one with constant nonzero
    cells, std 0) is returned with its nonzero cells centred only."""
    flat = grid.reshape(grid.shape[0], -1) if grid.ndim == 4 else grid.reshape(1, -1)
    mask = flat != 0
    n = mask.sum(1, keepdim=True).clamp(min=1).to(flat.dtype)
    mean = flat.sum(1, keepdim=True) / n
    var = ((flat * flat).sum(1, keepdim=True) / n - mean * mean).clamp(min=0)
    std = torch.sqrt(var)
    std = torch.where(std > 1e-8, std, torch.ones_like(std))
    out = torch.where(mask, (flat - mean) / std, torch.zeros_like(flat))
    return out.reshape(grid.shape)
