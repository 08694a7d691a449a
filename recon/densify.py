"""3DGS adaptive density control on a GaussianModel: gradient statistics, clone / split / prune and
opacity reset (Kerbl et al. 2023, as in the public 3DGS / D3DGS code).

The view-space gradient is the gradient of the loss w.r.t. the projected means in normalised device
coordinates: d/d(pixel) x (W/2, H/2), which is what the public code's 2e-4 threshold refers to.
"""
from __future__ import annotations

import torch

from recon.config import DensifyConfig
from recon.gaussians import GaussianModel, inverse_sigmoid
from recon.raster import RenderOutput


class DensifyStats:
    """Per-Gaussian accumulators between densification steps."""

    def __init__(self, n: int, device: torch.device | str = "cpu"):
        self.grad_accum = torch.zeros(n, device=device)     # [N] sum of NDC gradient norms over the views that saw it
        self.count = torch.zeros(n, device=device)          # [N] number of such views
        self.max_radii = torch.zeros(n, device=device)      # [N] largest screen radius (pixels) seen

    def __len__(self) -> int:
        return self.grad_accum.shape[0]

    def add(self, out: RenderOutput, width: int, height: int, pixel_scale: int = 1) -> None:
        """Accumulate one render's statistics (call after backward; means2d must have kept its grad).
        A render `pixel_scale` times coarser than the training images (coarse-to-fine) counts its radii
        in full-resolution pixels; the NDC gradient needs no scaling (it is resolution-free)."""
        visible = out.radii > 0
        radii = out.radii[visible].to(self.max_radii.dtype) * pixel_scale
        self.max_radii[visible] = torch.maximum(self.max_radii[visible], radii)
        g = out.means2d.grad
        if g is None:
            return
        g = g.detach() * torch.tensor([0.5 * width, 0.5 * height], dtype=g.dtype, device=g.device)
        self.grad_accum[visible] += g[visible].norm(dim=-1).to(self.grad_accum.dtype)
        self.count[visible] += 1

    def keep(self, mask: torch.Tensor) -> None:
        """Drop the rows of pruned Gaussians (mask [N] bool: kept)."""
        self.grad_accum, self.count, self.max_radii = self.grad_accum[mask], self.count[mask], self.max_radii[mask]

    def reset(self, n: int) -> None:
        self.__init__(n, self.grad_accum.device)

    def state_dict(self) -> dict:
        return {"grad_accum": self.grad_accum.cpu(), "count": self.count.cpu(), "max_radii": self.max_radii.cpu()}

    def load_state_dict(self, state: dict) -> None:
        device = self.grad_accum.device
        self.grad_accum, self.count, self.max_radii = (state[k].to(device).clone()
                                                       for k in ("grad_accum", "count", "max_radii"))


def densify_and_prune(model: GaussianModel, stats: DensifyStats, cfg: DensifyConfig, extent: float,
                      optimizer, prune_large: bool, generator: torch.Generator | None = None,
                      extra_prune: torch.Tensor | None = None) -> dict[str, int]:
    """One 3DGS densification step. Returns the counts {cloned, split, pruned}.

    Clone: mean NDC gradient >= threshold and largest scale <= percent_dense x extent.
    Split (into 2): same gradient test, larger scale. Prune: opacity < min_opacity, and when
    `prune_large` also screen radius > max_screen_size or largest scale > max_world_size x extent;
    `extra_prune` [N] (bool, before densification) adds a method's own criterion (e.g. IIP).
    """
    n0 = len(model)
    grads = stats.grad_accum / stats.count.clamp_min(1)
    grads[stats.count == 0] = 0.0
    big_grad = grads >= cfg.grad_threshold
    room = max(cfg.max_gaussians - n0, 0)
    with torch.no_grad():
        max_scale = model.scales.max(dim=1).values
    small = max_scale <= cfg.percent_dense * extent
    clone = big_grad & small
    split = big_grad & ~small
    # respect the cap: keep the largest gradients first
    n_clone, n_split = int(clone.sum()), int(split.sum())
    if n_clone + n_split > room:
        order = torch.argsort(grads, descending=True)
        allowed = torch.zeros(n0, dtype=torch.bool, device=model.means.device)
        allowed[order[:room]] = True
        clone &= allowed
        split &= allowed
        n_clone, n_split = int(clone.sum()), int(split.sum())
    extra = torch.zeros(n0, dtype=torch.bool, device=model.means.device) if extra_prune is None else extra_prune.clone()
    big_screen = stats.max_radii > cfg.max_screen_size
    if n_clone:
        model.clone_selected(clone, optimizer)
        split = torch.cat([split, torch.zeros(n_clone, dtype=torch.bool, device=model.means.device)])
        extra = torch.cat([extra, extra[clone]])
        big_screen = torch.cat([big_screen, big_screen[clone]])
    if n_split:
        keep = ~split
        model.split_selected(split, 2, optimizer, generator)
        extra = torch.cat([extra[keep], extra[split].repeat(2)])
        big_screen = torch.cat([big_screen[keep], torch.zeros(2 * n_split, dtype=torch.bool, device=model.means.device)])
    with torch.no_grad():
        prune = model.opacities < cfg.min_opacity
        if prune_large:
            prune |= big_screen | (model.scales.max(dim=1).values > cfg.max_world_size * extent)
        prune |= extra
    n_pruned = int(prune.sum())
    if n_pruned:
        model.prune(~prune, optimizer)
    stats.reset(len(model))
    return {"cloned": n_clone, "split": n_split, "pruned": n_pruned}


def reset_opacity(model: GaussianModel, optimizer, ceiling: float = 0.01) -> None:
    """Opacity reset: clamp every opacity to at most `ceiling`, zeroing its Adam moments."""
    with torch.no_grad():
        new = inverse_sigmoid(torch.clamp(model.opacities, max=ceiling))
    model._replace(optimizer, "opacity_logits", new, lambda s: torch.zeros_like(s))
