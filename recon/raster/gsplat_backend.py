"""The `gsplat` backend (CUDA): gsplat's fused projection and tile rasterizer behind our API.

Same conventions (OpenCV world_to_cam, pixel centres at +0.5, eps2d = 0.3 dilation, near plane
0.01, 3-sigma radii, alpha cap 0.99 and skip below 1/255, T stop at 1e-4). Differences: gsplat
decides tile membership per tile rather than per pixel of the footprint square (contributions with
alpha up to ~0.01 at footprint corners can differ), and it does not report each Gaussian's largest
compositing weight, so `max_weight` is NaN here; intensity-importance pruning needs the `cpu`
backend. Not exercised by this project's CI (no GPU); the GPU test in tests/test_raster.py runs
where CUDA is present.
"""
from __future__ import annotations

import torch

from recon.raster.types import LOWPASS, NEAR_PLANE, Camera, RenderOutput, TILE


def render_gsplat(means, quats, scales, opacities, colors, camera: Camera, background) -> RenderOutput:
    from gsplat import rasterization

    C = colors.shape[1]
    image, alphas, meta = rasterization(
        means, quats, scales, opacities, colors,
        viewmats=camera.world_to_cam[None], Ks=camera.K[None], width=camera.width, height=camera.height,
        near_plane=NEAR_PLANE, eps2d=LOWPASS, packed=False, tile_size=TILE, backgrounds=None,
        render_mode="RGB+D")
    rgb, depth = image[0, ..., :C], image[0, ..., C]
    alpha = alphas[0, ..., 0]
    rgb = rgb + (1.0 - alpha)[..., None] * background
    radii = meta["radii"][0]
    if radii.ndim == 2:  # newer gsplat reports x and y radii
        radii = radii.max(dim=-1).values
    max_weight = torch.full_like(opacities, float("nan"))
    return RenderOutput(rgb, alpha, depth, radii.to(torch.int32), meta["means2d"][0], max_weight)
