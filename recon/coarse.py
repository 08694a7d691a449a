"""Coarse-to-fine supervision as pure functions: a camera that renders an image `factor` times
smaller, and targets reduced to the same pixels.

A coarse pixel (i, j) covers the fine pixels [factor i, factor (i + 1)) x [factor j, factor (j + 1));
the fine image is cropped to whole blocks (at most factor - 1 columns and rows at the right and
bottom edges drop out of the coarse stages). Pixel (u, v) samples the image plane at (u + 0.5,
v + 0.5), so dividing fx, fy, cx, cy by the factor puts each coarse sample at its block's centre.

Targets are reduced the way the fine ones were made: an sRGB frame is decoded to linear light,
averaged over each block and re-encoded (light adds linearly; a blurred frame, itself a mean in
linear light, reduces consistently). Event counts are averaged: N is linear in log intensity, so the
block mean of N is the change of the block's mean log intensity. The coarse render samples a
smoothed image (its Gaussians are dilated by the rasterizer's 0.3 px low-pass in coarse pixels), so
its log is the log of a local mean of linear light, not the mean of the logs: the two agree where a
block is uniform, and differ at strong edges; the fine stages supervise those.
"""
from __future__ import annotations

import torch
import torch.nn.functional as F

from recon import event_supervision as ev
from recon.raster import Camera


def coarse_camera(camera: Camera, factor: int) -> Camera:
    """The camera rendering whole factor x factor blocks of `camera`'s pixels ([W // factor, H // factor])."""
    if factor == 1:
        return camera
    scale = torch.tensor([1.0 / factor, 1.0 / factor, 1.0], dtype=camera.K.dtype, device=camera.K.device)
    return Camera(camera.K * scale[:, None], camera.world_to_cam, camera.width // factor, camera.height // factor)


def block_mean(image: torch.Tensor, factor: int) -> torch.Tensor:
    """[H, W] or [H, W, C] -> the mean over each whole factor x factor block ([H // f, W // f(, C)])."""
    if factor == 1:
        return image
    h, w = image.shape[0] // factor, image.shape[1] // factor
    flat = image[:h * factor, :w * factor]
    planes = flat[None, None] if flat.dim() == 2 else flat.permute(2, 0, 1)[None]
    pooled = F.avg_pool2d(planes, factor)[0]
    return pooled[0] if flat.dim() == 2 else pooled.permute(1, 2, 0)


def coarse_srgb(image: torch.Tensor, factor: int) -> torch.Tensor:
    """An sRGB-encoded frame [H, W, C] reduced to coarse pixels: the block mean in linear light, re-encoded."""
    if factor == 1:
        return image
    return ev.linear_to_srgb_t(block_mean(ev.srgb_to_linear_t(image), factor))

